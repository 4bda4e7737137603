import sys

from clonedrive.cli import main

sys.exit(main())
