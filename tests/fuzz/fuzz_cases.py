# SPDX-License-Identifier: LGPL-2.1-or-later
"""The fuzz corpus: hostile and messy command lines, each with the files it needs.

A :class:`Case` names its input files (bytes built by ``fuzz_meshes``), the command line
(``{in}/NAME`` is an input, ``{old}/NAME`` an output file that already exists before the
run, ``{out}/NAME`` an output that does not) and the exit codes it may end with. Most
cases are rejected at intake or parameter validation; a handful of tiny valid ones run
the pipeline as far as ``--stop-after`` says.
"""
from dataclasses import dataclass, field

import numpy as np

import fuzz_meshes as fm

DIR = object()
"""A file entry that is a folder instead of a file."""


@dataclass(frozen=True)
class Case:
    """One run of the command line.

    name : pytest id.
    argv : command line after ``python -m polycube_wb``, with ``{in}``, ``{old}`` and
        ``{out}`` placeholders (see the module docstring).
    files : input file name -> bytes, or :data:`DIR` for a folder of that name.
    codes : exit codes the case may end with (0 success, 2 bad input).
    words : substrings the ``error:`` line must contain when the exit code is 2.
    subprocess : run ``python -m polycube_wb`` in a child process instead of in-process.
    """

    name: str
    argv: tuple
    files: dict = field(default_factory=dict)
    codes: tuple = (2,)
    words: tuple = ()
    subprocess: bool = False


def intake(name, file, data, codes=(2,), words=(), extra=(), stop="intake", sub=False,
           more_files=None):
    """A ``reconstruct`` case on one input file (plus ``more_files``, name -> bytes) that
    writes a report over an existing one."""
    argv = ("reconstruct", "{in}/" + file, "--stop-after", stop, "--report", "{old}/r.json") + tuple(extra)
    return Case(name, argv, {file: data, **(more_files or {})}, codes, words, sub)


SHAPES = {
    # name: (shape, exit codes, words of the error)
    "box": (fm.box(), (0,), ()),
    "tetrahedron": (fm.tetrahedron(), (0,), ()),
    "sphere": (fm.sphere(1), (0,), ()),
    "inside_out": (fm.inside_out(fm.box()), (0,), ()),
    "mixed_winding": (fm.mixed_winding_box(), (0,), ()),
    "thin_wall": (fm.box(extents=(1.0, 1.0, 1e-4)), (0,), ()),
    "huge_1e30": (fm.scaled(fm.box(), 1e30), (2,), ("coordinates reach 5e+29 mm",)),
    "tiny_1e-30": (fm.scaled(fm.box(), 1e-30), (2,), ("too small",)),
    "far_from_origin": (fm.box(center=(2e7, 0.0, 0.0)), (2,), ("coordinates reach",)),
    "overlapping_components": (fm.concatenate(fm.box(), fm.box(center=(0.3, 0.2, 0.1))), (0,), ()),
    "two_thousand_components": (fm.many_tetrahedra(2000), (0,), ()),
    "single_triangle": ((fm.tetrahedron()[0], fm.tetrahedron()[1][:1]), (2,), ("boundary edges",)),
    "collinear": (fm.collinear_soup(), (2,), ("degenerate",)),
    "coplanar_two_sided": (fm.flat_square_both_sides(), (2,), ("duplicate faces",)),
    "duplicated_surface": (fm.concatenate(fm.box(), fm.box()), (0,), ()),  # one copy kept
    "vertex_fan": (fm.boxes_sharing_a_vertex(), (2,), ("non-manifold vertices",)),
    "edge_fan": (fm.boxes_sharing_an_edge(), (2,), ("non-manifold edges",)),
    "fin": (fm.box_with_fin(), (2,), ("boundary edges",)),
    "self_intersecting": (fm.crossed_box(), (2,), ("intersecting faces",)),
    "nan_vertex": (fm.with_vertex(fm.box(), 0, np.nan), (2,), ("NaN or infinite",)),
    "inf_vertex": (fm.with_vertex(fm.box(), 3, np.inf), (2,), ("NaN or infinite",)),
}


def shape_cases():
    """Every shape in every format the intake reads; the repairable ones once more with
    ``--no-mesh-repair``, which refuses them."""
    cases = []
    for shape_name, (shape, codes, words) in SHAPES.items():
        for kind, writer in fm.WRITERS.items():
            suffix = kind.rsplit(".", 1)[-1]
            cases.append(intake(f"shape-{shape_name}-{kind}", f"{shape_name}.{suffix}",
                                writer(shape), codes, words))
    cases.append(intake("shape-duplicated_surface-strict", "d.obj",
                        fm.obj_text(fm.concatenate(fm.box(), fm.box())),
                        words=("duplicate faces",), extra=("--no-mesh-repair",)))
    return cases


def binary_stl_cases():
    good = fm.binary_stl(fm.sphere(1))
    count = len(fm.sphere(1)[1])
    cases = [intake(f"stl-truncated-{n}", "t.stl", good[:n], words=words)
             for n, words in ((1, ("truncated",)), (50, ("truncated",)), (83, ("truncated",)),
                              (84, ("truncated",)), (84 + 50 * 7 + 13, ("truncated",)),
                              (len(good) - 1, ("truncated",)))]
    for declared, words in ((0, ("corrupt",)), (count // 2, ("corrupt",)),
                            (2 ** 32 - 1, ("truncated",))):
        data = good[:80] + np.uint32(declared).tobytes() + good[84:]
        cases.append(intake(f"stl-declares-{declared}", "t.stl", data, words=words))
    cases.append(intake("stl-binary-with-solid-header", "t.stl", b"solid binary" + good[12:], (0,)))
    cases.append(intake("stl-trailing-bytes", "t.stl", good + b"\0" * 7, words=("corrupt",)))
    for seed in range(10):
        cases.append(intake(f"stl-corrupted-{seed}", "t.stl", fm.corrupt(good, seed, 3 + seed),
                            (0, 2)))
    return cases


def ascii_stl_cases():
    good = fm.ascii_stl(fm.box()).decode()
    lines = good.splitlines()
    variants = {
        "junk-only": ("solid x\nthis is not a facet\nendsolid x\n", (2,)),
        "truncated": (good[: len(good) // 2], (2,)),
        "letters-in-vertex": (good.replace("vertex 0.5", "vertex abc", 1), (2,)),
        "two-vertices": ("\n".join(lines[:4] + lines[5:]) + "\n", (2,)),
        "four-vertices": ("\n".join(lines[:5] + lines[4:5] + lines[5:]) + "\n", (2,)),
        "nan-vertex": (good.replace("vertex -0.5 -0.5 -0.5", "vertex nan nan nan"), (2,)),
        "overflow-vertex": (good.replace("vertex -0.5 -0.5 -0.5", "vertex 1e400 0 0"), (2,)),
        "solid-only": ("solid nothing\n", (2,)),
        "crlf": (good.replace("\n", "\r\n"), (0,)),
        "tabs-and-indent": (good.replace(" ", "\t"), (0,)),
        "junk-between-facets": (good.replace("endfacet\n", "endfacet\nnoise 1 2 3\n", 1), (0, 2)),
        "missing-endloop": (good.replace(" endloop\n", ""), (0, 2)),
        "latin1-name": (good.replace("solid fuzz", "solid caf\xe9"), (0, 2)),
    }
    return [intake(f"ascii-stl-{name}", "a.stl",
                   text.encode("latin-1") if name == "latin1-name" else text.encode(), codes)
            for name, (text, codes) in variants.items()]


def obj_cases():
    V, F = fm.box()
    vertices = "".join("v %r %r %r\n" % tuple(p) for p in V)
    good = _obj_faces(F + 1)
    quads = fm.cube_cage()
    variants = {
        "index-out-of-range": (vertices + good + "f 1 2 99\n", (2,), ("line 21", "out of range")),
        "index-zero": (vertices + _obj_faces(F), (2,), ()),
        "negative-beyond-count": (vertices + good + "f -1 -2 -99\n", (2,), ()),
        "negative-relative": (vertices + _obj_faces(F - len(V)), (0,), ()),
        "fractional-index": (vertices + good + "f 1.5 2 3\n", (2,), ()),
        "vertex-two-coordinates": ("v 1 2\n" + vertices + _obj_faces(F + 2), (2,), ()),
        "vertex-letters": ("v a b c\n" + vertices + _obj_faces(F + 2), (2,), ()),
        "vertices-only": (vertices, (2,), ("0 faces",)),
        "faces-only": (good, (2,), ()),
        "repeated-corner": (vertices + good + "f 1 2 2 3\n", (2,), ()),
        "two-corner-face": (vertices + good + "f 1 2\n", (2,), ()),
        "quads": (fm.cage_obj(*quads).decode(), (0,), ()),
        "slashes": (vertices + "".join("vt 0 0\nvn 0 0 1\n" for _ in V)
                    + _obj_faces([[f"{i}/{i}/{i}" for i in row] for row in F + 1]), (0,), ()),
        "groups-materials-comments": ("# c\nmtllib x.mtl\ng a\nusemtl m\n" + vertices
                                      + "s off\n" + good, (0,), ()),
        "unreferenced-nan-vertex": (vertices + "v nan nan nan\n" + good, (0,), ()),
        "unreferenced-far-vertex": (vertices + "v 1e300 1e300 1e300\n" + good, (0,), ()),
        "nan-vertex": ("v nan 0 0\n" + vertices[vertices.index("\n") + 1:] + good, (2,), ("NaN",)),
        "overflow-vertex": ("v 1e400 0 0\n" + vertices[vertices.index("\n") + 1:] + good, (2,), ()),
        "big-ngon": (_ngon_prism_obj(200), (0,), ()),
        "binary-garbage": (None, (2,), ()),
    }
    cases = []
    for name, (text, codes, words) in variants.items():
        data = bytes(range(256)) * 8 if text is None else text.encode()
        cases.append(intake(f"obj-{name}", "m.obj", data, codes, words))
    return cases


def _obj_faces(rows):
    """OBJ ``f`` records of the given corner rows (written as they are)."""
    return "".join("f " + " ".join(map(str, row)) + "\n" for row in rows)


def _ngon_prism_obj(n):
    """A prism over a regular ``n``-gon: two ``n``-gon caps and ``n`` quads (OBJ text)."""
    angle = 2 * np.pi * np.arange(n) / n
    ring = np.stack([np.cos(angle), np.sin(angle), np.zeros(n)], axis=1)
    V = np.vstack([ring, ring + [0.0, 0.0, 1.0]])
    faces = [list(range(n))[::-1], list(range(n, 2 * n))]
    faces += [[i, (i + 1) % n, n + (i + 1) % n, n + i] for i in range(n)]
    return fm.cage_obj(V, faces).decode()


def off_ply_cases():
    V, F = fm.box()
    off = fm.off_text((V, F)).decode()
    ply = fm.ply_binary((V, F))
    header_end = ply.index(b"end_header\n") + len(b"end_header\n")
    ascii_ply = fm.ply_ascii((V, F)).decode()
    variants = {
        "m.off": {
            "counts-too-large": off.replace("8 12 0", "80 120 0"),
            "counts-negative": off.replace("8 12 0", "-8 12 0"),
            "index-out-of-range": off.rstrip("\n").rsplit("\n", 1)[0] + "\n3 0 1 42\n",
            "two-corner-face": off.rstrip("\n").rsplit("\n", 1)[0] + "\n2 0 1\n",
            "no-header": off.split("\n", 1)[1],
            "letters": off.replace("OFF\n8 12 0", "OFF\neight twelve zero"),
        },
        "m.ply": {
            "header-only": ply[:header_end],
            "truncated-body": ply[: header_end + 40],
            "index-out-of-range": ply[:-4] + np.int32(99).tobytes(),
            "negative-index": ply[:-4] + np.int32(-5).tobytes(),
            "ascii-too-few-lines": ascii_ply.rstrip("\n").rsplit("\n", 3)[0] + "\n",
            "unknown-type": ascii_ply.replace("property float x", "property quaternion x"),
            "no-magic": ascii_ply.replace("ply\n", "", 1),
        },
    }
    cases = []
    for file, texts in variants.items():
        for name, text in texts.items():
            data = text if isinstance(text, bytes) else text.encode()
            cases.append(intake(f"{file.split('.')[1]}-{name}", file, data, (2,)))
    return cases


def file_cases():
    good = fm.binary_stl(fm.box())
    cases = [intake(f"empty-{ext}", "e." + ext, b"", words=("empty",)) for ext in
             ("stl", "obj", "ply", "off")]
    cases += [intake(f"not-a-mesh-{ext}", "n." + ext, b"hello, I am a letter\n" * 40)
              for ext in ("stl", "obj", "ply", "off")]
    cases += [intake(f"random-bytes-{ext}", "r." + ext,
                     np.random.default_rng(7).integers(0, 256, 4000, dtype=np.uint8).tobytes())
              for ext in ("stl", "obj", "ply", "off")]
    cases += [
        intake("a-folder", "folder.stl", DIR, words=("is a folder",)),
        intake("unsupported-extension", "m.step", b"ISO-10303-21;", words=("unsupported",)),
        intake("no-extension", "mesh", good, words=("unsupported",)),
        intake("uppercase-extension", "BOX.STL", good, (0,)),
        intake("spaces-and-unicode-name", "my b\u00f6x.stl", good, (0,)),
        Case("missing-file", ("reconstruct", "{in}/none.stl", "--stop-after", "intake",
                              "--report", "{old}/r.json"), {}, (2,), ("no such file",)),
        Case("no-arguments", ("reconstruct",), {}, (2,), ("required",)),
        Case("unknown-command", ("explode", "{in}/b.stl"), {"b.stl": good}, (2,), ("invalid choice",)),
        Case("unknown-option", ("reconstruct", "{in}/b.stl", "--frobnicate"), {"b.stl": good},
             (2,), ("unrecognized",)),
    ]
    return cases


INT_OPTIONS = {"--max-sweeps": (1, 100_000), "--target-faces": (6, 200_000),
               "--max-base-faces": (6, 1_000_000), "--subdivision-levels": (1, 5),
               "--fit-iterations": (0, 100_000)}
FLOAT_OPTIONS = {"--lam": (0.0, 1e3), "--penalty": (0.0, 1e12), "--blend-factor": (1e-3, 1e3)}
VALUES = ("-1", "0", "nan", "inf", "-inf", "1e300", "abc", "", "99999999999999999999")


def _accepted(text, low, high, integer):
    """Whether ``text`` is a valid value of an option with range ``low..high``."""
    try:
        value = int(text) if integer else float(text)
    except ValueError:
        return False
    return low <= value <= high


def parameter_cases():
    box = fm.binary_stl(fm.box())
    cases = []
    for options, integer in ((INT_OPTIONS, True), (FLOAT_OPTIONS, False)):
        for option, (low, high) in options.items():
            for value in VALUES:
                ok = _accepted(value, low, high, integer)
                cases.append(intake(f"param{option}={value or 'empty'}", "b.stl", box,
                                    (0,) if ok else (2,), () if ok else (option.strip("-").split("-")[0],),
                                    extra=(option, value)))
    tolerances = {"0.002": 0, "0.5mm": 0, "0.05 cm": 0, "-1": 2, "nan": 2, "inf": 2, "2": 2,
                  "-0.5mm": 2, "nanmm": 2, "1e30mm": 2, "mm": 2, "0.5furlong": 2, "": 2}
    for value, code in tolerances.items():
        cases.append(intake(f"param--tolerance={value or 'empty'}", "b.stl", box, (code,),
                            ("tolerance",) if code else (), extra=("--tolerance", value)))
    for option in ("--units", "--components", "--parts", "--fit-mode", "--base-mesh-method",
                   "--stop-after"):
        cases.append(intake(f"param{option}=bogus", "b.stl", box, (2,), ("invalid choice",),
                            extra=(option, "bogus")))
    for name, factor, unit, words in (
            ("1e300", 1e300, "mm", "coordinates reach 5e+299 mm"),
            ("1e306-in-metres", 1e306, "m", "coordinates reach 5e+305 x 1000 = inf mm"),
            ("1e5-in-metres", 1e5, "m", "coordinates reach 5e+04 x 1000 = 5e+07 mm"),
            ("1e-300", 1e-300, "mm", "too small"), ("1e-200-in-inches", 1e-200, "in", "too small")):
        cases.append(intake(f"coordinates-{name}", "b.obj", fm.obj_text(fm.scaled(fm.box(), factor)),
                            (2,), (words,), extra=("--units", unit)))
    cases.append(intake("param-tolerance-with-fit-none", "b.stl", box, (2,), ("tolerance",),
                        extra=("--tolerance", "0.01", "--fit-mode", "none")))
    return cases


def parts_file_cases():
    box = fm.binary_stl(fm.box())
    texts = {
        "not-json": b"{face_part: [0, 1",
        "a-list": b"[0, 0, 0]",
        "two-keys": b'{"face_part": [0], "groups": [[0]]}',
        "no-key": b'{"parts": []}',
        "face-part-short": b'{"face_part": [0, 0, 1]}',
        "face-part-strings": b'{"face_part": ["a", "b", "c", "d", "e", "f", "g", "h", "i", "j", "k", "l"]}',
        "face-part-negative": b'{"face_part": [0, 0, 0, 0, 0, 0, -1, -1, -1, -1, -1, -1]}',
        "face-part-nan": b'{"face_part": [0, 0, 0, 0, 0, 0, NaN, 1, 1, 1, 1, 1]}',
        "face-part-fractions": b'{"face_part": [0, 0, 0, 0, 0, 0, 0.5, 1, 1, 1, 1, 1]}',
        "face-part-nested": b'{"face_part": [[0, 1], [1, 0]]}',
        "groups-out-of-range": b'{"groups": [[0, 1, 2], [3, 4, 99]]}',
        "groups-negative": b'{"groups": [[0, 1, 2], [-3]]}',
        "groups-not-lists": b'{"groups": 5}',
        "planes-nan": b'{"planes": [[[0, 0, 0], [NaN, 0, 0]]]}',
        "planes-zero-normal": b'{"planes": [[[0, 0, 0], [0, 0, 0]]]}',
        "planes-wrong-shape": b'{"planes": [[0, 0, 0]]}',
        "planes-strings": b'{"planes": [[["a", 0, 0], [1, 0, 0]]]}',
        "binary": bytes(range(256)),
    }
    cases = [intake(f"parts-file-{name}", "b.stl", box, (2,), ("parts file",),
                    extra=("--parts-file", "{in}/parts.json"), stop="parts",
                    more_files={"parts.json": text})
             for name, text in texts.items()]
    cases.append(intake("parts-file-missing", "b.stl", box, (2,), ("cannot read the parts file",),
                        extra=("--parts-file", "{in}/none.json"), stop="parts"))
    cases.append(Case("parts-file-is-the-report",
                      ("reconstruct", "{in}/b.stl", "--stop-after", "parts", "--parts-file",
                       "{in}/parts.json", "--report", "{in}/parts.json"),
                      {"b.stl": box, "parts.json": b'{"planes": [[[0, 0, 0], [1, 0, 0]]]}'},
                      (2,), ("overwrite the input file",)))
    return cases


def output_cases():
    box = fm.binary_stl(fm.box())
    run = ("reconstruct", "{in}/b.stl")
    files = {"b.stl": box}
    return [
        Case("output-report-over-input", run + ("--stop-after", "intake", "--report", "{in}/b.stl"),
             files, (2,), ("overwrite the input file",)),
        Case("output-step-over-input", run + ("-o", "{in}/b.stl"), files, (2,),
             ("overwrite the input file",)),
        Case("output-labels-over-input", run + ("--stop-after", "labeling", "--labels", "{in}/b.stl"),
             files, (2,), ("overwrite the input file",)),
        Case("output-report-is-a-folder", run + ("--stop-after", "intake", "--report", "{in}/dir"),
             {**files, "dir": DIR}, (2,), ("folder",)),
        Case("output-folder-missing", run + ("--stop-after", "intake", "--report", "{out}/no/r.json"),
             files, (2,), ("does not exist",)),
        Case("output-step-missing", run + ("--report", "{old}/r.json"), files, (2,), ("-o",)),
        Case("output-base-mesh-before-basemesh", run + ("--stop-after", "labeling", "--report",
             "{old}/r.json", "--base-mesh", "{out}/b.obj"), files, (2,), ("base mesh", "--stop-after")),
        Case("output-labels-before-labeling", run + ("--stop-after", "intake", "--report",
             "{old}/r.json", "--labels", "{out}/l.ply"), files, (2,), ("labels file", "'labeling'")),
        Case("output-step-before-solid", run + ("--stop-after", "fit", "--report", "{old}/r.json",
             "-o", "{out}/s.step"), files, (2,), ("STEP file", "'solid'")),
        Case("output-two-outputs-one-file", run + ("--stop-after", "labeling", "--report",
             "{old}/x", "--labels", "{old}/x"), files, (2,), ("same file",)),
    ]


def cage_cases():
    V, faces = fm.cube_cage()
    cube = fm.cage_obj(V, faces)
    pushed = V.copy()
    pushed[6] = [-0.5, 0.5, 0.5]
    variants = {
        "valid": (cube, (0,), ()),
        "open": (fm.cage_obj(V, faces[:-1]), (2,), ("open",)),
        "inverted": (fm.cage_obj(V, [f[::-1] for f in faces]), (2,), ("inward",)),
        "flipped-face": (fm.cage_obj(V, faces[:-1] + [faces[-1][::-1]]), (2,), ("orient",)),
        "vertex-fan": (fm.cage_obj(np.vstack([V, V[1:] + 1.0]),
                                   faces + [[6 if i == 0 else i + 7 for i in f] for f in faces]),
                       (2,), ("non-manifold vertices",)),
        "repeated-corner": (fm.cage_obj(V, faces[:-1] + [faces[-1][:3] + [faces[-1][0]]]), (2,), ()),
        "nan-vertex": (fm.cage_obj(fm.with_vertex((V, None), 0, np.nan)[0], faces), (2,), ("NaN",)),
        "huge-coordinates": (fm.cage_obj(V * 1e15, faces), (2,), ("coordinates reach",)),
        "tiny": (fm.cage_obj(V * 1e-6, faces), (2,), ("too small",)),
        "self-intersecting": (fm.cage_obj(*fm.spindle_torus_cage()), (2,),
                              ("intersects itself", "between base faces")),
        "overlapping-components": (fm.cage_obj(np.vstack([V, V + 0.2]),
                                               faces + [[i + 8 for i in f] for f in faces]),
                                   (2,), ("2 separate components",)),
        "pushed-through": (fm.cage_obj(pushed, faces), (0, 2), ()),
        "two-components": (fm.cage_obj(np.vstack([V, V + 3.0]),
                                       faces + [[i + 8 for i in f] for f in faces]), (2,),
                           ("2 separate components",)),
        "unreferenced-vertex": (fm.cage_obj(np.vstack([V, [[9.0, 9.0, 9.0]]]), faces), (2,),
                                ("used by no face",)),
        "index-out-of-range": (cube + b"f 1 2 30\n", (2,), ("out of range",)),
        "index-zero": (cube + b"f 0 1 2\n", (2,), ("start at 1",)),
        "letters": (b"v a b c\n" + cube, (2,), ()),
        "no-faces": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", (2,), ()),
        "binary": (bytes(range(256)), (2,), ("binary",)),
        "latin1": (cube.replace(b"v ", b"v\xe9 ", 1), (2,), ()),
        "empty": (b"", (2,), ()),
    }
    cases = [Case(f"cage-{name}", ("subd-to-step", "{in}/c.obj", "-o", "{old}/c.step",
                                   "--report", "{out}/r.json", "--no-measure"),
                  {"c.obj": data}, codes, words) for name, (data, codes, words) in variants.items()]
    cases.append(Case("cage-folder", ("subd-to-step", "{in}/c.obj", "-o", "{out}/c.step"),
                      {"c.obj": DIR}, (2,), ("cannot read",)))
    for value in ("-1", "0", "13", "nan", "abc", "1e3"):
        cases.append(Case(f"cage--depth={value}", ("subd-to-step", "{in}/c.obj", "-o",
                                                   "{old}/c.step", "--depth", value),
                          {"c.obj": cube}, (2,), ("depth",)))
    cases.append(Case("cage-step-over-input", ("subd-to-step", "{in}/c.obj", "-o", "{in}/c.obj"),
                      {"c.obj": cube}, (2,), ("overwrite the input file",)))
    return cases


def check_cases():
    box = fm.binary_stl(fm.box())
    check = ("check", "{in}/b.stl", "{in}/r.step", "--report", "{old}/c.json")
    return [
        Case("check-result-missing", check, {"b.stl": box}, (2,), ("r.step",)),
        Case("check-result-empty", check, {"b.stl": box, "r.step": b""}, (2,), ("r.step",)),
        Case("check-result-not-step", check, {"b.stl": box, "r.step": b"hello\n" * 10}, (2,),
             ("r.step",)),
        Case("check-result-folder", check, {"b.stl": box, "r.step": DIR}, (2,), ("r.step",)),
        Case("check-target-empty", check, {"b.stl": b"", "r.step": b"ISO-10303-21;"}, (2,),
             ("empty",)),
        Case("check-report-over-target", ("check", "{in}/b.stl", "{in}/r.step", "--report",
                                          "{in}/b.stl"), {"b.stl": box, "r.step": b"x"}, (2,),
             ("overwrite the input file",)),
    ]


def batch_cases():
    box = fm.binary_stl(fm.box())
    batch = ("batch", "{in}/b.stl", "-o", "{out}/batch", "--quiet")
    cases = [Case(f"batch{option}={value}", batch + (option, value), {"b.stl": box}, (2,),
                  (option,))
             for option, value in (("--jobs", "0"), ("--jobs", "-1"), ("--jobs", "abc"),
                                   ("--timeout", "0"), ("--timeout", "-1"), ("--timeout", "nan"))]
    cases += [
        Case("batch-bad-lam", batch + ("--lam", "-1"), {"b.stl": box}, (2,), ("lam",)),
        Case("batch-no-meshes", ("batch", "{in}/*.stl", "-o", "{out}/batch"), {}, (2,), ()),
        Case("batch-overrides-missing", batch + ("--overrides", "{in}/none.json"), {"b.stl": box},
             (2,), ("none.json",)),
        Case("batch-overrides-not-json", batch + ("--overrides", "{in}/o.json"),
             {"b.stl": box, "o.json": b"{oops"}, (2,), ("o.json",)),
        Case("batch-overrides-unknown-parameter", batch + ("--overrides", "{in}/o.json"),
             {"b.stl": box, "o.json": b'{"*": {"frobnicate": 1}}'}, (2,), ("frobnicate",)),
        Case("batch-overrides-bad-value", batch + ("--overrides", "{in}/o.json"),
             {"b.stl": box, "o.json": b'{"*": {"lam": -5}}'}, (2,), ("lam",)),
    ]
    return cases


def pipeline_cases():
    """The few tiny valid runs that go past intake."""
    box = fm.binary_stl(fm.box())
    sphere = fm.binary_stl(fm.sphere(2))
    return [
        Case("run-box-labeling", ("reconstruct", "{in}/b.stl", "--stop-after", "labeling",
                                  "--labels", "{old}/l.ply", "--report", "{out}/r.json"),
             {"b.stl": box}, (0,)),
        Case("run-sphere-basemesh", ("reconstruct", "{in}/s.stl", "--stop-after", "basemesh",
                                     "--base-mesh", "{old}/b.obj", "--report", "{old}/r.json"),
             {"s.stl": sphere}, (0,)),
        Case("run-box-solid", ("reconstruct", "{in}/b.stl", "-o", "{out}/b.step",
                               "--fit-iterations", "2", "--base-mesh", "{out}/b.obj"),
             {"b.stl": box}, (0,)),
        Case("run-box-parts-planes", ("reconstruct", "{in}/b.stl", "--stop-after", "parts",
                                      "--parts-file", "{in}/p.json", "--report", "{out}/r.json"),
             {"b.stl": box, "p.json": b'{"planes": [[[0.1, 0, 0], [1, 0, 0]]]}'}, (0,)),
    ]


def subprocess_cases():
    """A few cases run as real processes: the exit code and stderr as a shell sees them."""
    box = fm.binary_stl(fm.box())
    picked = [
        intake("sub-empty-stl", "e.stl", b"", words=("empty",), sub=True),
        intake("sub-truncated-stl", "t.stl", box[:100], words=("truncated",), sub=True),
        intake("sub-nan-obj", "n.obj", fm.obj_text(fm.with_vertex(fm.box(), 0, np.nan)),
               words=("NaN",), sub=True),
        intake("sub-bad-lam", "b.stl", box, words=("lam",), extra=("--lam", "nan"), sub=True),
        intake("sub-valid-box", "b.stl", box, (0,), sub=True),
    ]
    V, faces = fm.cube_cage()
    picked.append(Case("sub-cage-huge", ("subd-to-step", "{in}/c.obj", "-o", "{old}/c.step"),
                       {"c.obj": fm.cage_obj(V * 1e15, faces)}, (2,), ("coordinates reach",), True))
    return picked


def all_cases():
    cases = (shape_cases() + binary_stl_cases() + ascii_stl_cases() + obj_cases() + off_ply_cases()
             + file_cases() + parameter_cases() + parts_file_cases() + output_cases()
             + cage_cases() + check_cases() + batch_cases() + pipeline_cases() + subprocess_cases())
    names = [case.name for case in cases]
    assert len(set(names)) == len(names), "fuzz case names must be unique"
    return cases
