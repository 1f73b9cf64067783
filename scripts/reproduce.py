#!/usr/bin/env python3
"""Reproduce a learned controller from a preset (``rabbit_policy.commands.reproduce``):
train -> screen -> ship -> evaluate -> model card, everything under --out.

    scripts/reproduce.py --preset tiny --out runs/tiny       # about a minute (CI runs it)
    scripts/reproduce.py --preset shipped --out runs/shipped # hours on 2 cores
"""

import sys

from rabbit_policy.commands.reproduce import main

if __name__ == "__main__":
    sys.exit(main())
