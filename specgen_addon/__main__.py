import sys

from specgen_addon.cli.app import main

sys.exit(main())
