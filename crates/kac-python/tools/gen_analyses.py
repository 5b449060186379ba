"""Writes python/kac/_analyses.py: one function per analysis of the engine's registry, with its options and their
descriptions from the request's JSON Schema (the service's OpenAPI document), so that the functions, their names
and their documentation follow from the registry. Run after adding an analysis:

    python crates/kac-python/tools/gen_analyses.py            # writes the file
    python crates/kac-python/tools/gen_analyses.py --check    # exits 1 if the file is not what it would write

It needs the native module built (pip install ./crates/kac-python).
"""

import json
import pathlib
import sys
import textwrap

from kac import _kac

OUT = pathlib.Path(__file__).resolve().parents[1] / "python" / "kac" / "_analyses.py"
# These have functions of their own in _core (spectrum returns arrays, operator SciPy matrices).
OWN = ("spectrum", "operator")


def camel(name: str) -> str:
    return "".join(p.capitalize() for p in name.replace("_", "-").split("-"))


def describe(schemas: dict, name: str) -> list:
    schema = schemas[f"{camel(name)}Analysis"]
    lines = []
    for key, prop in sorted(schema.get("properties", {}).items()):
        if key == "analysis":
            continue
        ref = prop.get("$ref") or next((a["$ref"] for a in prop.get("oneOf", []) if "$ref" in a), None)
        text = (prop.get("description") or "").replace("\n", " ")
        if ref:
            target = schemas[ref.rsplit("/", 1)[-1]]
            nested = ", ".join(sorted(target.get("properties", {})))
            if nested:
                text = (text + " " if text else "") + f"Its fields may be given directly: {nested}."
        lines.append(f"- ``{key}``: {text}".rstrip(": "))
    return lines


def render() -> str:
    table = json.loads(_kac.analyses())["analyses"]
    schemas = json.loads(_kac.openapi())["components"]["schemas"]
    out = [
        '"""One function per analysis of the registry, written by tools/gen_analyses.py from the registry and the',
        "requests' JSON Schemas (do not edit by hand; a test checks it is current).\"\"\"",
        "",
        "from __future__ import annotations",
        "",
        "from typing import Any",
        "",
        "from ._core import Progress, Result, ShapeLike, analyze",
        "",
    ]
    names = []
    for row in table:
        name = row["name"]
        if name in OWN:
            continue
        py = name.replace("-", "_")
        names.append(py)
        doc = [row["summary"].rstrip(".") + ".", ""]
        doc += textwrap.wrap(
            f"Applies to: {', '.join(row['classes'])}. Accuracy: {row['accuracy']}", 112
        ) + [""]
        if row.get("takes_operator"):
            doc += [
                "Sign convention: L = the weak form of Δ = −∇·∇ (positive semidefinite), L φ = λ M φ, eigenvalues",
                "ascending, eigenvectors M-orthonormal.",
                "",
            ]
        doc += [f"Options (the service's ``{camel(name)}Analysis``, ``kac {name} --help``):", ""]
        for line in describe(schemas, name):
            doc += textwrap.wrap(line, 112, subsequent_indent="  ")
        doc += ["", "Returns a :class:`Result`: the summary's fields, and ``arrays`` (rows: the input's vertices)."]
        body = "\n".join(("    " + d) if d else "" for d in doc)
        out += [
            "",
            f"def {py}(",
            "    s: ShapeLike, faces: Any = None, *, threads: int = 0, progress: Progress = None, **options: Any",
            ") -> Result:",
            f'    """{body.lstrip()}',
            '    """',
            f'    return analyze("{name}", s, faces, threads=threads, progress=progress, **options)',
            "",
        ]
    out += ["", "__all__ = [" + ", ".join(f'"{n}"' for n in names) + "]", ""]
    return "\n".join(out)


if __name__ == "__main__":
    text = render()
    if "--check" in sys.argv:
        sys.exit(0 if OUT.read_text() == text else 1)
    OUT.write_text(text)
