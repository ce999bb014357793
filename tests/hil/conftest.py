"""Make ``import hil`` resolve to the package, not to this folder, and share emulator fixtures.

pytest's default (prepend) import mode puts ``tests/`` on sys.path, where ``tests/hil``
(no ``__init__.py``) would shadow the real ``hil`` as a namespace package; the repository
root goes first instead (``pythonpath = ["."]`` in pytest's ini options would do the same).
"""

import sys
from pathlib import Path

ROOT = str(Path(__file__).resolve().parents[2])
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)
