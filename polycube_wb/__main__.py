# SPDX-License-Identifier: LGPL-2.1-or-later
"""``python -m polycube_wb``: see :mod:`polycube_wb.cli`."""
import sys

from polycube_wb.cli import main

sys.exit(main())
