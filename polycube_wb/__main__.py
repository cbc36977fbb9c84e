# SPDX-License-Identifier: LGPL-2.1-or-later
"""``python -m polycube_wb``: see :mod:`polycube_wb.cli`."""
import sys

try:
    from polycube_wb.cli import EXIT_CANCELLED, main
except KeyboardInterrupt:  # Ctrl-C while the modules load: nothing ran yet
    sys.stderr.write("cancelled at start-up; nothing was written\n")
    sys.exit(130)
sys.exit(main())
