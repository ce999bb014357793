"""Make ``import osnerf``/``phy`` resolve to the packages, not to folders of ``tests/``.

pytest's prepend import mode puts ``tests/`` on sys.path, where ``tests/osnerf`` and
``tests/phy`` (no ``__init__.py``) would shadow the real packages as namespace packages.
"""

import sys
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[2])
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
