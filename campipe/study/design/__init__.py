"""``campipe design``: the values of a spec's keys that meet its requirements best (its
``design:`` section, :mod:`campipe.study.spec.design`): each design evaluated by the onset
search and the engine (:mod:`~campipe.study.design.evaluate`), the search
(:mod:`~campipe.study.design.search`), its table and file (:mod:`~campipe.study.design.output`).
"""
