"""The thesis's printed matrices (Figures 11–14), as read from the OCR copy.

Only the upper triangle is given; the matrices are symmetric. Where the OCR dropped a sign
from one of a symmetric pair, the entry is taken from its readable twin: C14 from row 4
(−21.0), C37 from row 7 (−.5), C57 from row 5 (−10.0); the diagonal C55 is printed −27.6,
a lost-sign OCR error for a positive diagonal. Blank entries ("0.0") are exact zeros.
"""

import numpy as np


def _symmetric(upper: dict[tuple[int, int], float]) -> np.ndarray:
    a = np.zeros((7, 7))
    for (i, j), v in upper.items():
        a[i - 1, j - 1] = a[j - 1, i - 1] = v
    return a


#: Figure 11, mass matrix ×1e-5 [lbf·s²/in, lbf·s², lbf·s²·in]
FIGURE_11 = _symmetric(
    {
        (1, 1): 15.5,
        (1, 2): -7.8,
        (2, 2): 23.2,
        (2, 3): 1.1,
        (2, 6): -0.6,
        (3, 3): 0.2,
        (3, 6): -0.1,
        (4, 4): 20.1,
        (4, 5): -2.4,
        (4, 6): 1.4,
        (4, 7): -2.6,
        (5, 5): 0.6,
        (5, 6): -0.5,
        (6, 6): 0.9,
        (7, 7): 5.2,
    }
)
FIGURE_11_SCALE = 1e-5

#: Figure 12, stiffness matrix ×1e5 [lbf/in, lbf, lbf·in]
FIGURE_12 = _symmetric(
    {
        (1, 1): 2.4,
        (1, 2): 2.4,
        (2, 2): 25.2,
        (2, 3): 11.5,
        (2, 6): 11.5,
        (3, 3): 7.6,
        (3, 6): 3.8,
        (4, 4): 13.8,
        (4, 5): -5.1,
        (4, 6): -5.1,
        (4, 7): 7.1,
        (5, 5): 5.1,
        (5, 6): 2.5,
        (6, 6): 12.7,
        (7, 7): 7.1,
    }
)
FIGURE_12_SCALE = 1e5

#: Figure 13, damping matrix ×1e-2 [lbf·s/in, lbf·s, lbf·s·in]
FIGURE_13 = _symmetric(
    {
        (1, 1): 92.3,
        (1, 2): 37.7,
        (1, 3): 3.7,
        (1, 4): -21.0,
        (1, 5): 2.9,
        (1, 6): -4.5,
        (1, 7): 6.0,
        (2, 2): 217.2,
        (2, 3): 33.1,
        (2, 4): 67.6,
        (2, 5): -18.6,
        (2, 6): 26.5,
        (2, 7): -10.7,
        (3, 3): 20.2,
        (3, 4): 7.2,
        (3, 5): -3.2,
        (3, 6): 0.1,
        (3, 7): -0.5,
        (4, 4): 178.0,
        (4, 5): -37.0,
        (4, 6): -0.9,
        (4, 7): 83.1,
        (5, 5): 27.6,
        (5, 6): -7.7,
        (5, 7): -10.0,
        (6, 6): 48.9,
        (6, 7): 4.6,
        (7, 7): 95.7,
    }
)
FIGURE_13_SCALE = 1e-2

#: Figure 14 natural frequencies [rad/s], ascending, with the lost decimal point of "736.5"
#: restored (73.65e3). The printed lowest, 691, is what a 253.9 lbf/in spring gives; the stated
#: 245 lbf/in gives 679.1.
FIGURE_14_FREQUENCIES = np.array([691.0, 25.9e3, 73.65e3, 146.7e3, 247.1e3, 521.9e3, 1070.2e3])
