# SPDX-License-Identifier: LGPL-2.1-or-later
"""Document objects of the workbench: one FeaturePython proxy per pipeline stage.

Proxies only, no GUI: ``target``, ``segmentation``, ``base_mesh``, ``fit``, ``solid`` and
``deviation`` each hold one proxy class; ``base`` holds what they share. Factories are in
``polycube_wb.api``, view providers and task panels in ``polycube_wb.gui``.

The module paths and class names here are part of the ``.FCStd`` file format (FreeCAD
stores them with every object): never move or rename them without leaving an alias.
"""
