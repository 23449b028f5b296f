"""``python -m validation.cli``: the ``diffuse-imaging`` command."""

import sys

from . import console

sys.exit(console())
