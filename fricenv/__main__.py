import sys

from fricenv.cli import main

sys.exit(main())
