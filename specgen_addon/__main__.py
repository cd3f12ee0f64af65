import sys

from specgen_addon.cli.entry import main

sys.exit(main())
