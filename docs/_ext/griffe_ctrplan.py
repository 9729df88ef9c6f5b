"""Griffe extension for the API reference: ctrplan's docstrings as mkdocstrings renders them.

The docstrings are numpydoc with Sphinx markup; mkdocstrings renders Markdown. On loading the
package this extension, without touching the sources:

- turns Sphinx roles (``:func:`~ctrplan.io.load_robot```, ``:mod:`.data```) into code that links to
  the object's entry where the reference has one (an optional autoref: plain code otherwise);
- turns ``:math:`x``` and ``.. math::`` blocks into arithmatex math (rendered by MathJax);
- adds the names a package imports on first use (a module-level ``_LAZY = {name: module}`` dict
  read by ``__getattr__``, PEP 562) as aliases, so they are documented with the package;
- gives a module-level constant without a docstring the ``#`` comment block right above it.
"""

from __future__ import annotations

import ast
import re
from html import escape

from griffe import Alias, Docstring, Extension, Module, Object

# A Sphinx cross-reference role: :func:`target`, :py:class:`~a.b.C`, ...
_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|attr|data|mod|exc|obj|const):`(?P<target>[^`]+)`")
# Inline math role.
_MATH_ROLE = re.compile(r":math:`(?P<tex>[^`]+)`")
# A math directive, its first line (the formula may start on it).
_MATH_BLOCK = re.compile(r"^(?P<indent>[ \t]*)\.\. math::[ \t]*(?P<first>.*)$")


class CtrplanDocs(Extension):
    """Rewrites ctrplan's docstrings into mkdocstrings' Markdown once the package is loaded."""

    def on_package(self, *, pkg: Module, **kwargs) -> None:
        if pkg.name != "ctrplan":
            return
        modules = list(_modules(pkg))
        for mod in modules:
            _add_lazy_names(mod)
        for mod in modules:
            _document_constants(mod)
        for obj in _objects(pkg):
            if obj.docstring is not None:
                obj.docstring.value = _markdown(obj.docstring.value, obj, pkg)


def _modules(mod: Module):
    yield mod
    for member in mod.modules.values():
        if not member.is_alias:
            yield from _modules(member)


def _objects(obj: Object):
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _objects(member)


def _module_tree(mod: Module) -> ast.Module | None:
    if mod.filepath is None or isinstance(mod.filepath, list):
        return None
    return ast.parse(mod.filepath.read_text(encoding="utf-8"))


def _add_lazy_names(mod: Module) -> None:
    if "_LAZY" not in mod.members:
        return
    tree = _module_tree(mod)
    for node in tree.body if tree else ():
        if (isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "_LAZY" for t in node.targets)
                and isinstance(node.value, ast.Dict)):
            for key, value in zip(node.value.keys, node.value.values):
                name, source = ast.literal_eval(key), ast.literal_eval(value)
                package = mod.path if mod.is_init_module else mod.parent.path
                target = f"{package}.{source.lstrip('.')}.{name}"
                if name not in mod.members:
                    mod.set_member(name, Alias(name, target, lineno=key.lineno, endlineno=key.lineno, parent=mod))


def _document_constants(mod: Module) -> None:
    lines = mod.lines
    for attr in mod.attributes.values():
        if attr.is_alias or attr.docstring is not None or not attr.lineno:
            continue
        comment = []
        i = attr.lineno - 2
        while i >= 0 and lines[i].startswith("#"):
            comment.insert(0, lines[i].removeprefix("#:").lstrip("#").strip())
            i -= 1
        if comment:
            attr.docstring = Docstring(" ".join(comment), lineno=attr.lineno, parent=attr,
                                       parser=mod.docstring.parser if mod.docstring else None,
                                       parser_options=mod.docstring.parser_options if mod.docstring else None)


def _markdown(text: str, obj: Object, pkg: Module) -> str:
    text = _math_blocks(text)
    text = _MATH_ROLE.sub(lambda m: f"${m['tex'].strip()}$", text)
    return _ROLE.sub(lambda m: _reference(m["target"], obj, pkg), text)


def _math_blocks(text: str) -> str:
    lines = text.split("\n")
    out = []
    i = 0
    while i < len(lines):
        m = _MATH_BLOCK.match(lines[i])
        if not m:
            out.append(lines[i])
            i += 1
            continue
        indent = len(m["indent"])
        tex = [m["first"].strip()] if m["first"].strip() else []
        i += 1
        while i < len(lines) and (not lines[i].strip() and not tex
                                  or lines[i].strip() and len(lines[i]) - len(lines[i].lstrip()) > indent):
            if lines[i].strip():
                tex.append(lines[i].strip())
            i += 1
        out += ["", m["indent"] + "$$", *(m["indent"] + t for t in tex), m["indent"] + "$$", ""]
    return "\n".join(out)


def _reference(target: str, obj: Object, pkg: Module) -> str:
    short = target.startswith("~")
    name = target.lstrip("~").removesuffix("()")
    shown = name.lstrip(".").rsplit(".", 1)[-1] if short else name.lstrip(".")
    path = _resolve(name, obj, pkg)
    code = f"<code>{escape(shown)}</code>"
    if path is None:
        return code
    return f'<autoref identifier="{escape(path)}" optional>{code}</autoref>'


def _resolve(name: str, obj: Object, pkg: Module) -> str | None:
    """The full path of ``name`` as written in the docstring of ``obj``, if it is in ``pkg``."""
    scope = obj if obj.is_module or obj.is_class else obj.parent
    candidates = []
    if name.startswith("."):
        module = obj.module
        base = module if module.is_init_module else module.parent
        candidates += [f"{module.path}{name}", f"{base.path}{name}"]
    else:
        head, _, rest = name.partition(".")
        while scope is not None:
            candidates.append(f"{scope.path}.{name}")
            if head in scope.members:
                member = scope.members[head]
                full = member.target_path if member.is_alias else member.path
                candidates.append(f"{full}.{rest}" if rest else full)
            scope = scope.parent
        candidates.append(name)
    for path in candidates:
        if _exists(path, pkg):
            return path
    return None


def _exists(path: str, pkg: Module) -> bool:
    head, _, rest = path.partition(".")
    if head != pkg.name:
        return False
    if not rest:
        return True
    try:
        pkg[rest]
    except Exception:  # missing member, or an alias to outside the package that cannot be resolved
        return False
    return True
