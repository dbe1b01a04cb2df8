"""The reference pages of docs/ that are written from the code, so that they cannot go stale:
``docs/api.md`` (the public API's signatures and docstrings) and ``docs/scenario-file.md`` (every
key of a scenario file, from the dataclasses and validators that read it; :mod:`mlpfac.pages.scenario_doc`).

    python -m mlpfac.pages docs            # write them
    python -m mlpfac.pages docs --check    # exit 1 when one differs from what the code gives

``tests/test_docs.py`` runs the check.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import sys
from pathlib import Path

from mlpfac.pages.scenario_doc import HEAD, scenario_page


def _doc(obj) -> str:
    return inspect.cleandoc(obj.__doc__ or "").strip()


def _param(p: inspect.Parameter) -> str:
    """``name: annotation = default``, the annotation as written in the source (no quotes)."""
    ann = p.annotation
    text = str(p.replace(annotation=inspect.Parameter.empty))
    if ann is inspect.Parameter.empty:
        return text
    name, eq, default = text.partition("=")
    ann = ann if isinstance(ann, str) else inspect.formatannotation(ann)
    return f"{name}: {ann}" + (f" = {default}" if eq else "")


def _signature(name: str, obj) -> str:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return name
    params, star = [], False
    for p in sig.parameters.values():
        if p.kind is p.VAR_POSITIONAL:
            star = True
        if p.kind is p.KEYWORD_ONLY and not star:
            params.append("*")
            star = True
        params.append(_param(p))
    ret = sig.return_annotation
    ret = (
        ""
        if ret is inspect.Signature.empty
        else f" -> {ret if isinstance(ret, str) else inspect.formatannotation(ret)}"
    )
    one = f"{name}({', '.join(params)}){ret}"
    if len(one) <= 100:
        return one
    return f"{name}(\n" + "".join(f"    {p},\n" for p in params) + f"){ret}"


def _value(obj) -> str:
    """A constant as ruff would format it: double quotes, a long tuple one item a line."""
    if isinstance(obj, str):
        return json.dumps(obj)
    if isinstance(obj, tuple) and all(isinstance(x, str) for x in obj):
        one = "(" + ", ".join(json.dumps(x) for x in obj) + ")"
        return one if len(one) < 100 else "(\n" + "".join(f"    {json.dumps(x)},\n" for x in obj) + ")"
    return repr(obj)


def _own_methods(cls) -> list[tuple[str, object]]:
    """The public methods and properties ``cls`` defines itself, in source order."""
    out = []
    for key, val in vars(cls).items():
        if key.startswith("_"):
            continue
        if isinstance(val, property | staticmethod | classmethod) or inspect.isfunction(val):
            out.append((key, val))
    return out


def _member(cls_name: str, key: str, val) -> list[str]:
    if isinstance(val, property):
        head, fn = f"{cls_name}.{key}  # a property", val.fget
    else:
        fn = val.__func__ if isinstance(val, staticmethod | classmethod) else val
        head = _signature(f"{cls_name}.{key}", fn).replace("(self, ", "(").replace("(self)", "()")
        head = head.replace("(cls, ", "(").replace("(cls)", "()")
    doc = _doc(fn)
    return ["```python", head, "```", "", *([doc, ""] if doc else [])]


def _section(name: str, obj) -> list[str]:
    lines = [f"## `mlpfac.{name}`", ""]
    if inspect.isclass(obj):
        bases = [b.__name__ for b in obj.__bases__ if b is not object]
        head = f"class {name}" + (f"({', '.join(bases)})" if bases else "")
        lines += ["```python", head, "```", "", _doc(obj), ""]
        if dataclasses.is_dataclass(obj):
            lines += ["| field | type |", "| --- | --- |"]
            lines += [f"| `{f.name}` | `{f.type}` |" for f in dataclasses.fields(obj)]
            lines.append("")
        for key, val in _own_methods(obj):
            lines += _member(name, key, val)
    elif callable(obj):
        lines += ["```python", _signature(name, obj), "```", "", _doc(obj), ""]
    else:
        lines += ["```python", f"{name} = {_value(obj)}", "```", ""]
    return lines


def api_page() -> str:
    """docs/api.md: every name of ``mlpfac.__all__``, with its signature and docstring."""
    import mlpfac

    lines = [
        "# The Python API",
        "",
        HEAD,
        "`import mlpfac` gives these names (`mlpfac.__all__`); each does what the command line does",
        "([The code](code.md#from-python) shows them in use). Bad input raises `mlpfac.ConfigError`",
        "(the command line's one line and exit 2). Signatures and text are the code's own.",
        "",
    ]
    for name in sorted(mlpfac.__all__, key=str.lower):
        lines += _section(name, getattr(mlpfac, name))
    return "\n".join(lines).rstrip() + "\n"


def pages() -> dict[str, str]:
    """File name in docs/ -> its text, as the code gives it now."""
    return {"api.md": api_page(), "scenario-file.md": scenario_page()}


def stale(docs: Path) -> list[str]:
    """The generated pages under ``docs`` that differ from what the code gives (or are missing)."""
    return [name for name, text in pages().items() if not (docs / name).is_file() or (docs / name).read_text() != text]


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    check = "--check" in args
    rest = [a for a in args if a != "--check"]
    if len(rest) != 1 or not Path(rest[0]).is_dir():
        print("usage: python -m mlpfac.pages DOCS_FOLDER [--check]", file=sys.stderr)
        return 2
    docs = Path(rest[0])
    old = stale(docs)
    if check:
        for name in old:
            print(f"{docs / name}: differs from what the code gives; run: python -m mlpfac.pages {docs}")
        return 1 if old else 0
    from mlpfac.io.files import write_atomic

    texts = pages()
    for name in texts:  # only our own pages are replaced: a regular file that says it is written here
        path = docs / name
        if path.exists() and (not path.is_file() or path.is_symlink() or HEAD not in path.read_text(errors="replace")):
            print(f"mlpfac: error: {path}: not a page written by mlpfac.pages; left as it is", file=sys.stderr)
            return 2
    for name, text in texts.items():
        write_atomic(docs / name, text)
    print(f"{len(texts)} pages written, {len(old)} changed")
    return 0
