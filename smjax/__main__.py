"""``python -m smjax ...`` is the ``smjax`` command."""
import sys

from smjax.cli import entry

sys.exit(entry())
