"""``python -m crossing_assist.export`` = ``crossing-export``."""

import sys

from crossing_assist.export.cli import main

sys.exit(main())
