import sys

from sasprobe.cli.main import main

sys.exit(main())
