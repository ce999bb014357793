"""Make ``import phy`` resolve to the package, not to this folder.

pytest's default (prepend) import mode puts ``tests/`` on sys.path, where ``tests/phy``
(no ``__init__.py``) would shadow the real ``phy`` as a namespace package. Putting the
repository root first fixes that; ``pythonpath = ["."]`` in pytest's ini options would too.
"""

import sys
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[2])
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
