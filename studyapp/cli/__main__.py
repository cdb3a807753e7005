"""``python -m studyapp.cli``: the same as the ``studyapp`` console script."""
import sys

from studyapp.cli import main

sys.exit(main())
