"""``python -m validation.cli``: the ``diffuse-imaging`` command."""

import sys

from . import main

sys.exit(main())
