# SPDX-License-Identifier: LGPL-2.1-or-later
"""Catmull-Clark subdivision as sparse matrices, limit masks and exact limit evaluation."""
