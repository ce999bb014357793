"""Make ``import osnerf`` resolve to the package, not to the ``tests/osnerf`` folder.

pytest's prepend import mode puts ``tests/`` on sys.path, where a ``tests/osnerf`` folder
(no ``__init__.py``) shadows the real package as a namespace package. Putting the
repository root first fixes that (``pythonpath = ["."]`` in pytest's ini options would too).
"""

import sys
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[2])
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
