import sys

from sasprobe.cli import main

sys.exit(main())
