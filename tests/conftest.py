import sys
from pathlib import Path

# The thesis's printed figures live beside the tests as plain data.
sys.path.insert(0, str(Path(__file__).parent))
