# SPDX-License-Identifier: LGPL-2.1-or-later
"""The Deviation colour map's legend: a colour bar with its scale drawn over the 3D view.

A head-up overlay (its own orthographic camera inside an ``SoAnnotation``) added to the
document's 3D view: the bar runs from blue (inside the target by ``ScaleUsed``) through
white to red (outside by ``ScaleUsed``), labelled in model units (mm) and in % of the
target's bounding-box diagonal.
"""
import FreeCADGui

_LEGENDS = {}
"""(document name, object name) -> (scene graph root, legend node)."""
SEGMENTS = 16
X0, X1, Y0, Y1 = -0.98, -0.92, -0.7, 0.7
"""Bar corners in the overlay camera's units (the view spans at least [-1, 1] each way)."""


def legend_texts(obj):
    """The five tick labels (bottom to top) of a Deviation object's legend."""
    scale = obj.ScaleUsed
    percent = 100.0 * scale / max(obj.Target.Mesh.BoundBox.DiagonalLength, 1e-300)
    ticks = (-1.0, -0.5, 0.0, 0.5, 1.0)
    return [f"{t * scale:+.3g} mm ({t * percent:+.2f} %)" for t in ticks]


def update_legend(obj):
    """Draw (or redraw) the legend of ``obj`` in its document's 3D view (only while the
    object is shown: the view provider adds and removes it with the visibility)."""
    from pivy import coin

    from polycube_wb.objects.deviation import deviation_colours

    remove_legend(obj)
    view = FreeCADGui.getDocument(obj.Document.Name).ActiveView
    if not hasattr(view, "getSceneGraph") or obj.ScaleUsed <= 0 or \
            not obj.ViewObject.Visibility:
        return
    node = coin.SoAnnotation()
    camera = coin.SoOrthographicCamera()
    camera.height.setValue(2.0)
    camera.position.setValue(0.0, 0.0, 5.0)
    camera.nearDistance.setValue(1.0)
    camera.farDistance.setValue(10.0)
    node.addChild(camera)
    light = coin.SoLightModel()
    light.model.setValue(coin.SoLightModel.BASE_COLOR)
    node.addChild(light)
    levels = [-1.0 + 2.0 * k / SEGMENTS for k in range(SEGMENTS + 1)]
    colours = deviation_colours(_array(levels), 1.0)
    material = coin.SoMaterial()
    material.diffuseColor.setValues(0, 2 * len(levels), [c for c in colours for _ in (0, 1)])
    node.addChild(material)
    binding = coin.SoMaterialBinding()
    binding.value.setValue(coin.SoMaterialBinding.PER_VERTEX_INDEXED)
    node.addChild(binding)
    points = []
    for level in levels:
        y = Y0 + (level + 1.0) / 2.0 * (Y1 - Y0)
        points += [(X0, y, 0.0), (X1, y, 0.0)]
    coordinates = coin.SoCoordinate3()
    coordinates.point.setValues(0, len(points), points)
    node.addChild(coordinates)
    faces = coin.SoIndexedFaceSet()
    index = []
    for k in range(SEGMENTS):
        index += [2 * k, 2 * k + 1, 2 * k + 3, 2 * k + 2, -1]
    faces.coordIndex.setValues(0, len(index), index)
    faces.materialIndex.setValues(0, len(index), index)
    node.addChild(faces)
    text_colour = coin.SoBaseColor()
    text_colour.rgb.setValue(0.0, 0.0, 0.0)
    node.addChild(text_colour)
    font = coin.SoFont()
    font.size.setValue(14.0)
    node.addChild(font)
    for k, text in enumerate(legend_texts(obj)):
        separator = coin.SoSeparator()
        place = coin.SoTranslation()
        place.translation.setValue(X1 + 0.02, Y0 + k / 4.0 * (Y1 - Y0), 0.0)
        separator.addChild(place)
        label = coin.SoText2()
        label.string.setValue(text)
        separator.addChild(label)
        node.addChild(separator)
    root = view.getSceneGraph()
    root.addChild(node)
    _LEGENDS[(obj.Document.Name, obj.Name)] = (root, node)


def remove_legend(obj):
    """Take the legend of ``obj`` out of the 3D view (idempotent)."""
    entry = _LEGENDS.pop((obj.Document.Name, obj.Name), None)
    if entry is not None:
        root, node = entry
        root.removeChild(node)


def has_legend(obj):
    return (obj.Document.Name, obj.Name) in _LEGENDS


def _array(values):
    import numpy as np

    return np.asarray(values, dtype=np.float64)
