"""``python -m smjax ...`` is the ``smjax`` command."""
import sys

from smjax.cli import main

sys.exit(main())
