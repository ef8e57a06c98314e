"""``python -m parallax_core ...`` runs the ``parallax`` console script."""
import sys

from .cli import main

sys.exit(main())
