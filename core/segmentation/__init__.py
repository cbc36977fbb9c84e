# SPDX-License-Identifier: LGPL-2.1-or-later
"""Polycube segmentation of a target mesh: parts, frames, labels and their validity."""
