import sys

from fogmon.cli import main

sys.exit(main())
