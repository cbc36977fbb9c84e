# SPDX-License-Identifier: LGPL-2.1-or-later
"""Export of the limit surface: bicubic B-spline patches as plain arrays."""
