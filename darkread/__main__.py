import sys

from darkread.cli import main

sys.exit(main())
