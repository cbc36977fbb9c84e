# SPDX-License-Identifier: LGPL-2.1-or-later
"""Colour legends drawn over the 3D view: the Deviation map's scale and the six label colours.

A legend is a head-up overlay docked at the left edge of the 3D view, halfway up, whatever
the view's size and aspect: its own orthographic camera maps the viewport to [-1, 1] both
ways (``LEAVE_ALONE``), and a scale node, kept at two viewport units per pixel by a callback
that reads the viewport at each redraw, lets the legend be laid out in pixels. A light panel
behind black text keeps it readable on any background (FreeCAD's default gradient included).
The overlay is left out of bounding boxes (``fitAll`` frames the model only) and picking.

The Deviation legend has the title "distance to target, mm", the bar from blue (the solid is
inside the target) through white to red (outside) with ticks in mm, what + and - mean, and
the largest distance in mm and % of the target's size; the model point where that distance is
gets a marker with the same figure (``MaxDeviationAt``).
"""
import FreeCADGui

from polycube_wb.objects.segmentation import LABEL_COLOURS

_LEGENDS = {}
"""(document name, object name) -> (scene graph root, overlay node, its render callback: a
Python function the scene graph calls, kept alive here as long as the node is shown)."""
SEGMENTS = 32
BAR = (14, 34, -100, 100)
"""Bar corners (left, right, bottom, top) in pixels from the left edge, halfway up."""
FONT_SIZE = 13
LINE = 17
"""Pixels from one text line to the next."""
CHAR_WIDTH = 7.2
"""Width of one character at ``FONT_SIZE`` (pixels; sizes the panel behind the text)."""
PANEL_COLOUR, PANEL_TRANSPARENCY = (1.0, 1.0, 1.0), 0.15
TEXT_COLOUR = (0.0, 0.0, 0.0)
MARKER_COLOUR = (0.0, 0.0, 0.0)
LABEL_NAMES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
"""Names of the six polycube labels, in label order (0 .. 5)."""
TICKS = (1.0, 0.25, 0.0, -0.25, -1.0)
"""Tick values as fractions of the scale, top to bottom (the colour follows the square root
of the distance: a quarter of the scale is half-way up the bar)."""


def legend_texts(obj):
    """The Deviation legend's lines: title, ticks top to bottom, the largest distance.

    Returns
    -------
    (title, ticks, largest) : str, list of (fraction of the bar's half-height, text), str.
    """
    scale = obj.ScaleUsed
    ticks = []
    for value in TICKS:
        meaning = " outside" if value == 1.0 else " inside" if value == -1.0 else ""
        text = "0 on the target" if value == 0 else f"{value * scale:+.3g}{meaning}"
        ticks.append((_bar_position(value), text))
    largest = f"largest: {obj.MaxDeviation:.3g} mm ({obj.MaxDeviationPercent:.2g} % of size)"
    return "distance to target, mm", ticks, largest


def _bar_position(fraction):
    """Height on the bar (-1 bottom .. 1 top) of a distance ``fraction`` of the scale."""
    return (1.0 if fraction > 0 else -1.0 if fraction < 0 else 0.0) * abs(fraction) ** 0.5


def update_legend(obj):
    """Draw (or redraw) the legend of Deviation ``obj`` and its marker of the largest
    distance in its document's 3D view (only while the object is shown: the view provider
    adds and removes it with the visibility)."""
    import numpy as np
    from pivy import coin

    from polycube_wb.objects.deviation import deviation_colours

    remove_legend(obj)
    view = _view(obj)
    if view is None or obj.ScaleUsed <= 0 or not obj.ViewObject.Visibility:
        return
    overlay, panel, callback = _overlay()
    title, ticks, largest = legend_texts(obj)
    left, right, bottom, top = BAR
    width = right + 12 + CHAR_WIDTH * max(len(text) for _, text in ticks)
    width = max(width, 8 + CHAR_WIDTH * max(len(title), len(largest)))
    _panel(panel, (2, width + 4, bottom - 2 * LINE - 12, top + LINE + 18))
    levels = np.linspace(-1.0, 1.0, SEGMENTS + 1)
    values = np.sign(levels) * levels ** 2  # the bar shows the square-root colour ramp
    _bar(panel, [bottom + (level + 1.0) / 2.0 * (top - bottom) for level in levels],
         deviation_colours(values, 1.0))
    _colour(panel, TEXT_COLOUR)
    _text(panel, (left - 4, top + 14), title)
    half = (top - bottom) / 2.0
    middle = (top + bottom) / 2.0
    for position, text in ticks:
        y = middle + position * half
        _lines(panel, [((right, y), (right + 5, y))])
        _text(panel, (right + 9, y - FONT_SIZE / 3.0), text)
    _text(panel, (left - 4, bottom - LINE - 4), largest)
    _text(panel, (left - 4, bottom - 2 * LINE - 4), "where: the circled + on the model")
    root = view.getSceneGraph()
    group = coin.SoSeparator()
    group.addChild(overlay)
    group.addChild(_marker(obj))
    root.addChild(group)
    _LEGENDS[(obj.Document.Name, obj.Name)] = (root, group, callback)


def update_label_legend(obj):
    """Draw (or redraw) the six label colours of a labeling Segmentation ``obj`` (+X, -X,
    ... beside their colour) in its document's 3D view, while it is shown."""
    remove_legend(obj)
    view = _view(obj)
    if view is None or not obj.ViewObject.Visibility:
        return
    overlay, panel, callback = _overlay()
    rows = len(LABEL_NAMES)
    top = rows * LINE / 2.0
    title = "polycube labels"
    _panel(panel, (2, 16 + CHAR_WIDTH * len(title), -top - 6, top + LINE + 8))
    _colour(panel, TEXT_COLOUR)
    _text(panel, (10, top + 4), title)
    for k, (name, colour) in enumerate(zip(LABEL_NAMES, LABEL_COLOURS)):
        y = top - (k + 1) * LINE
        _box(panel, (10, 30, y + 2, y + LINE - 3), colour)
        _colour(panel, TEXT_COLOUR)
        _text(panel, (36, y + 4), name)
    root = view.getSceneGraph()
    root.addChild(overlay)
    _LEGENDS[(obj.Document.Name, obj.Name)] = (root, overlay, callback)


def remove_legend(obj):
    """Take the legend of ``obj`` out of the 3D view (idempotent)."""
    entry = _LEGENDS.pop((obj.Document.Name, obj.Name), None)
    if entry is not None:
        root, node, _ = entry
        root.removeChild(node)


def has_legend(obj):
    return (obj.Document.Name, obj.Name) in _LEGENDS


# ----------------------------------------------------------------------------------------
# Scene-graph pieces
# ----------------------------------------------------------------------------------------

def _view(obj):
    """The 3D view of ``obj``'s document, or None (no GUI document or not a 3D view)."""
    gui_doc = FreeCADGui.getDocument(obj.Document.Name)
    view = gui_doc.ActiveView if gui_doc is not None else None
    return view if hasattr(view, "getSceneGraph") else None


def _overlay():
    """(overlay node for the scene graph, separator to add the legend to in pixels, the
    render callback to keep alive while the overlay is shown).

    The separator's origin is the left edge of the viewport, halfway up; x to the right and
    y up in pixels.
    """
    from pivy import coin

    overlay = coin.SoType.fromName("SoSkipBoundingGroup").createInstance()
    annotation = coin.SoAnnotation()
    overlay.addChild(annotation)
    pick = coin.SoPickStyle()
    pick.style.setValue(coin.SoPickStyle.UNPICKABLE)
    annotation.addChild(pick)
    camera = coin.SoOrthographicCamera()
    camera.viewportMapping.setValue(coin.SoCamera.LEAVE_ALONE)
    camera.aspectRatio.setValue(1.0)
    camera.height.setValue(2.0)
    camera.position.setValue(0.0, 0.0, 5.0)
    camera.nearDistance.setValue(1.0)
    camera.farDistance.setValue(10.0)
    annotation.addChild(camera)
    light = coin.SoLightModel()
    light.model.setValue(coin.SoLightModel.BASE_COLOR)
    annotation.addChild(light)
    place = coin.SoTranslation()
    place.translation.setValue(-1.0, 0.0, 0.0)
    annotation.addChild(place)
    pixels = coin.SoScale()
    callback_node, callback = _pixel_callback(pixels)
    annotation.addChild(callback_node)
    annotation.addChild(pixels)
    _font(annotation)
    panel = coin.SoSeparator()
    annotation.addChild(panel)
    return overlay, panel, callback


def _pixel_callback(scale):
    """(callback node, its Python function) keeping ``scale`` at two viewport units per pixel
    of the viewport being drawn (the 3D view, or an offscreen image of another size)."""
    from pivy import coin

    size = []  # the viewport (width, height) the scale was set for

    def adjust(_data, action):
        if not action.isOfType(coin.SoGLRenderAction.getClassTypeId()):
            return
        region = coin.SoViewportRegionElement.get(action.getState())
        width, height = region.getViewportSizePixels().getValue()
        if size != [width, height]:  # setting the field redraws: only when the size changed
            size[:] = [width, height]
            scale.scaleFactor.setValue(2.0 / max(width, 1), 2.0 / max(height, 1), 1.0)

    node = coin.SoCallback()
    node.setCallback(adjust)
    return node, adjust


def _panel(parent, corners):
    """A light, slightly transparent rectangle (left, right, bottom, top) behind the text."""
    from pivy import coin

    separator = coin.SoSeparator()
    material = coin.SoMaterial()
    material.diffuseColor.setValue(*PANEL_COLOUR)
    material.transparency.setValue(PANEL_TRANSPARENCY)
    separator.addChild(material)
    _quad(separator, corners)
    parent.addChild(separator)


def _box(parent, corners, colour):
    """A rectangle (left, right, bottom, top) of ``colour`` with a thin dark outline."""
    from pivy import coin

    separator = coin.SoSeparator()
    base = coin.SoBaseColor()
    base.rgb.setValue(*colour)
    separator.addChild(base)
    _quad(separator, corners)
    parent.addChild(separator)
    left, right, bottom, top = corners
    _colour(parent, TEXT_COLOUR)
    _lines(parent, [((left, bottom), (right, bottom)), ((right, bottom), (right, top)),
                    ((right, top), (left, top)), ((left, top), (left, bottom))])


def _quad(parent, corners):
    from pivy import coin

    left, right, bottom, top = corners
    coordinates = coin.SoCoordinate3()
    coordinates.point.setValues(0, 4, [(left, bottom, 0.0), (right, bottom, 0.0),
                                       (right, top, 0.0), (left, top, 0.0)])
    parent.addChild(coordinates)
    face = coin.SoFaceSet()
    face.numVertices.setValue(4)
    parent.addChild(face)


def _bar(parent, heights, colours):
    """The colour bar between ``BAR``'s left and right, one band per pair of ``heights``
    (pixels, bottom to top), coloured per vertex with ``colours`` (one per height)."""
    from pivy import coin

    left, right = BAR[0], BAR[1]
    separator = coin.SoSeparator()
    material = coin.SoMaterial()
    material.diffuseColor.setValues(0, 2 * len(colours), [c for c in colours for _ in (0, 1)])
    separator.addChild(material)
    binding = coin.SoMaterialBinding()
    binding.value.setValue(coin.SoMaterialBinding.PER_VERTEX_INDEXED)
    separator.addChild(binding)
    points = [(x, y, 0.0) for y in heights for x in (left, right)]
    coordinates = coin.SoCoordinate3()
    coordinates.point.setValues(0, len(points), points)
    separator.addChild(coordinates)
    index = []
    for k in range(len(heights) - 1):
        index += [2 * k, 2 * k + 1, 2 * k + 3, 2 * k + 2, -1]
    faces = coin.SoIndexedFaceSet()
    faces.coordIndex.setValues(0, len(index), index)
    faces.materialIndex.setValues(0, len(index), index)
    separator.addChild(faces)
    parent.addChild(separator)
    _colour(parent, TEXT_COLOUR)
    bottom, top = heights[0], heights[-1]
    _lines(parent, [((left, bottom), (right, bottom)), ((right, bottom), (right, top)),
                    ((right, top), (left, top)), ((left, top), (left, bottom))])


def _colour(parent, rgb):
    from pivy import coin

    base = coin.SoBaseColor()
    base.rgb.setValue(*rgb)
    parent.addChild(base)


def _lines(parent, segments):
    """Line segments ``((x0, y0), (x1, y1))`` in pixels."""
    from pivy import coin

    separator = coin.SoSeparator()
    coordinates = coin.SoCoordinate3()
    points = [(x, y, 0.0) for segment in segments for x, y in segment]
    coordinates.point.setValues(0, len(points), points)
    separator.addChild(coordinates)
    lines = coin.SoLineSet()
    lines.numVertices.setValues(0, len(segments), [2] * len(segments))
    separator.addChild(lines)
    parent.addChild(separator)


def _text(parent, at, text):
    """One line of text whose baseline starts at ``at`` (pixels)."""
    from pivy import coin

    separator = coin.SoSeparator()
    place = coin.SoTranslation()
    place.translation.setValue(at[0], at[1], 0.0)
    separator.addChild(place)
    label = coin.SoText2()
    label.string.setValue(text)
    separator.addChild(label)
    parent.addChild(separator)


def _marker(obj):
    """A cross at ``MaxDeviationAt`` with the largest distance beside it, drawn over the
    model (an annotation) so that it shows from every side."""
    from pivy import coin

    annotation = coin.SoAnnotation()
    pick = coin.SoPickStyle()
    pick.style.setValue(coin.SoPickStyle.UNPICKABLE)
    annotation.addChild(pick)
    light = coin.SoLightModel()
    light.model.setValue(coin.SoLightModel.BASE_COLOR)
    annotation.addChild(light)
    at = getattr(obj, "MaxDeviationAt", None)
    if at is None:
        return annotation
    place = coin.SoTranslation()
    place.translation.setValue(at.x, at.y, at.z)
    annotation.addChild(place)
    _colour(annotation, MARKER_COLOUR)
    coordinates = coin.SoCoordinate3()
    coordinates.point.setValue(0.0, 0.0, 0.0)
    annotation.addChild(coordinates)
    for marker in (coin.SoMarkerSet.PLUS_9_9, coin.SoMarkerSet.CIRCLE_LINE_9_9):
        markers = coin.SoMarkerSet()
        markers.markerIndex.setValue(marker)
        annotation.addChild(markers)
    _font(annotation)
    label = coin.SoText2()
    label.string.setValue(f"  largest {obj.MaxDeviation:.3g} mm")
    annotation.addChild(label)
    return annotation


def _font(node):
    """Add the legends' font (sans, ``FONT_SIZE`` points) to ``node``."""
    from pivy import coin

    font = coin.SoFont()
    font.name.setValue("sans")
    font.size.setValue(FONT_SIZE)
    node.addChild(font)
