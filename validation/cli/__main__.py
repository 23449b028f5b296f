"""``python -m validation.cli``: the ``diffuse-imaging`` command."""

import sys

from .program import console

sys.exit(console())
