"""`python -m onboard.upload`: upload one flight to the ground app (see `onboard.upload.client`)."""

import sys

from onboard.upload.client import main

sys.exit(main())
