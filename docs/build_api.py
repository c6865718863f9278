"""Write docs/api.md, the API reference, from the signatures and docstrings of :mod:`identcheck.api` and of the
result classes its verbs return (the standard library's :mod:`inspect` only).

    python docs/build_api.py            # rewrite docs/api.md
    python docs/build_api.py --check    # exit 1 when docs/api.md is not what this script writes

``tests/docs/test_docs_sync.py`` runs the check: a docstring edited without rerunning this script fails it.
"""
from __future__ import annotations

import argparse
import importlib
import inspect
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "api.md"

CLASSES = (
    ("identcheck.fit.result", "FitResult"),
    ("identcheck.diagnose.workflow", "Diagnosis"),
    ("identcheck.plan.result", "PlanResult"),
    ("identcheck.certify.table", "TableResult"),
    ("identcheck.certify.exact_rank", "RankCertificate"),
    ("identcheck.certify.verify", "VerifyResult"),
    ("identcheck.identify", "IdentifyResult"),
    ("identcheck.identify", "JointIdentification"),
    ("identcheck.infer.result", "SkeletonResult"),
    ("identcheck.derive.result", "DeriveResult"),
    ("identcheck.simulate.rigid", "Simulation"),
    ("identcheck.io.model", "Model"),
    ("identcheck.io.model", "Segment"),
    ("identcheck.io.model", "Joint"),
    ("identcheck.trial", "Trial"),
    ("identcheck.errors", "InputError"),
    ("identcheck.errors", "DegenerateError"),
    ("identcheck.errors", "IdentifiabilityWarning"),
    ("identcheck.errors", "KindedWarning"),
    ("identcheck.errors", "UnitsWarning"),
)
"""The result and input classes, in the order the reference lists them (those that do not exist are left out)."""

SECTIONS = ("Parameters", "Returns", "Raises", "Attributes", "Yields", "Warns", "See Also", "Notes", "Examples",
            "References", "Other Parameters")
ROLE = re.compile(r":(?:func|meth|mod|class|data|attr|obj|exc|ref):`~?([^`]+)`")


def _annotation(a) -> str:
    return a if isinstance(a, str) else inspect.formatannotation(a)


def _default(value) -> str:
    text = repr(value)
    return re.sub(r" at 0x[0-9a-f]+", "", text)


def signature(obj, skip_self: bool = False) -> str:
    """``(a, b: int = 0, *, c=None)`` written the same way on every Python version (no memory addresses)."""
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return "(...)"
    parts, star_done = [], False
    params = list(sig.parameters.values())
    if skip_self and params and params[0].name in ("self", "cls"):
        params = params[1:]
    for p in params:
        if p.kind is p.KEYWORD_ONLY and not star_done:
            parts.append("*")
            star_done = True
        text = {p.VAR_POSITIONAL: "*", p.VAR_KEYWORD: "**"}.get(p.kind, "") + p.name
        star_done |= p.kind is p.VAR_POSITIONAL
        if p.annotation is not p.empty:
            text += f": {_annotation(p.annotation)}"
        if p.default is not p.empty:
            text += (" = " if p.annotation is not p.empty else "=") + _default(p.default)
        parts.append(text)
    out = f"({', '.join(parts)})"
    if sig.return_annotation is not sig.empty:
        out += f" -> {_annotation(sig.return_annotation)}"
    return out


def markdown(doc: str | None) -> str:
    """A numpydoc docstring as Markdown: section titles bold, parameters as list items, examples as code."""
    if not doc:
        return "*(no docstring)*\n"
    doc = ROLE.sub(r"`\1`", doc).replace("``", "`")
    lines = doc.splitlines()
    out, section, i, in_code = [], None, 0, False
    while i < len(lines):
        line = lines[i]
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if line.strip() in SECTIONS and nxt.strip() and set(nxt.strip()) == {"-"}:
            if in_code:
                out.append("```")
                in_code = False
            section = line.strip()
            out += ["", f"**{section}**", ""]
            i += 2
            continue
        stripped = line.strip()
        if stripped.startswith(">>>") or (in_code and stripped and not stripped.startswith(">>>")
                                          and section == "Examples"):
            if not in_code:
                out.append("```python")
                in_code = True
            out.append(stripped)
        elif in_code and not stripped:
            out.append("```")
            in_code = False
            out.append("")
        elif section in ("Parameters", "Returns", "Raises", "Attributes", "Yields", "Warns", "Other Parameters") \
                and stripped and not line.startswith(" "):
            name, _, kind = stripped.partition(" : ")
            out.append(f"- `{name}`" + (f" ({kind})" if kind else ""))
        elif section in ("Parameters", "Returns", "Raises", "Attributes", "Yields", "Warns", "Other Parameters") \
                and stripped:
            out.append(f"  {stripped}")
        else:
            out.append(line)
        i += 1
    if in_code:
        out.append("```")
    text = "\n".join(out).strip("\n")
    return re.sub(r"\n{3,}", "\n\n", text) + "\n"


def _members(cls) -> list:
    """Public methods and properties defined on `cls` itself, in source order."""
    out = []
    for name, value in vars(cls).items():
        if name.startswith("_") and name not in ("__init__",):
            continue
        if name == "__init__":
            continue
        if isinstance(value, property):
            out.append((name, "property", value.fget))
        elif isinstance(value, (classmethod, staticmethod)):
            out.append((name, "classmethod" if isinstance(value, classmethod) else "staticmethod", value.__func__))
        elif inspect.isfunction(value):
            out.append((name, "method", value))
    return out


def _verbs():
    api = importlib.import_module("identcheck.api")
    found = [(name, f) for name, f in vars(api).items()
             if inspect.isfunction(f) and not name.startswith("_") and f.__module__ == api.__name__]
    return sorted(found, key=lambda nf: inspect.unwrap(nf[1]).__code__.co_firstlineno)


def render() -> str:
    """The whole of docs/api.md."""
    api = importlib.import_module("identcheck.api")
    parts = ["# API reference", "",
             "*Generated by `python docs/build_api.py` from the signatures and docstrings; do not edit by hand "
             "(`tests/docs/test_docs_sync.py` checks that it is up to date).*", "",
             "Every verb of the command line is one function of `identcheck.api`, also importable from `identcheck` "
             "itself (`import identcheck as ic; ic.fit(...)`; `derive` and `identify` only from `identcheck.api`). "
             "Each returns a frozen result whose `to_dict()` is what `identcheck VERB --json` prints "
             "([json.md](json.md)). Command line: [cli.md](cli.md); model files: [model.md](model.md).", "",
             "## Verbs: `identcheck.api`", "", markdown(inspect.getdoc(api)), ""]
    verbs = _verbs()
    parts += ["| function | returns |", "|---|---|"]
    for name, f in verbs:
        first = ROLE.sub(r"`\1`", (inspect.getdoc(f) or "").split("\n\n")[0]).replace("``", "`").replace("\n", " ")
        parts.append(f"| [`{name}`](#{name}) | {first.replace('|', '/')} |")
    parts.append("")
    for name, f in verbs:
        parts += [f"### {name}", "", "```python", f"identcheck.api.{name}{signature(f)}", "```", "",
                  markdown(inspect.getdoc(f)), ""]
    parts += ["## Results and inputs", ""]
    for module, name in CLASSES:
        try:
            cls = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError):
            continue
        parts += [f"### {name}", "", "```python", f"{module}.{name}{signature(cls)}", "```", "",
                  markdown(inspect.getdoc(cls)), ""]
        for member, kind, f in _members(cls):
            sig = "" if kind == "property" else signature(f, skip_self=kind != "staticmethod")
            label = {"property": " *(property)*", "classmethod": " *(classmethod)*",
                     "staticmethod": " *(staticmethod)*"}.get(kind, "")
            doc = inspect.getdoc(f)
            parts += [f"#### `{name}.{member}{sig}`{label}", "", markdown(doc) if doc else "", ""]
    text = "\n".join(parts)
    return re.sub(r"\n{3,}", "\n\n", text).rstrip("\n") + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="exit 1 when docs/api.md is out of date; write nothing")
    a = ap.parse_args(argv)
    text = render()
    if a.check:
        current = OUT.read_text(encoding="utf-8") if OUT.exists() else ""
        if current != text:
            print(f"{OUT} is out of date: run python docs/build_api.py", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text, encoding="utf-8")
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    sys.exit(main())
