"""``python -m posegraph``: the ``posegraph`` command."""

import sys

from posegraph_cli.main import main

sys.exit(main())
