"""The type stubs (the package's __init__.pyi) against the module, both ways: every
public name of the module has a stub and every stub a name; every class's members
likewise; every function's and method's parameters (names, order, keyword-only marker)
equal the signature pybind11 gives the compiled one."""

import ast
import inspect
import pathlib

import pytest

import vmap

# Dunder methods a stub declares because they make a class usable from Python (iteration,
# with-blocks, len, truth, equality, unpacking); other dunders are pybind11's own.
PROTOCOL = {"__init__", "__iter__", "__next__", "__len__", "__enter__", "__exit__", "__bool__", "__eq__",
            "__contains__", "__getitem__"}


@pytest.fixture(scope="module")
def stub():
    path = pathlib.Path(vmap.__file__).with_name("__init__.pyi")
    assert path.exists(), f"{path} is missing: the build joins it from examples/python/stubs"
    assert (path.parent / "py.typed").exists()
    return ast.parse(path.read_text(), filename=str(path))


def public(name):
    return not name.startswith("_")


def stub_top_level(tree):
    names = {}
    for node in tree.body:
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)):
            names[node.name] = node
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names[node.target.id] = node
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                if isinstance(t, ast.Name):
                    names[t.id] = node
    return names


def test_every_module_name_has_a_stub_and_every_stub_a_name(stub):
    stubs = {n for n in stub_top_level(stub) if public(n)} | {"__version__"}
    module = {n for n in dir(vmap) if public(n)} | {"__version__"}
    assert module - stubs == set(), "names of the module without a stub"
    assert stubs - module == set(), "stubs without a name in the module"


def members(cls_node):
    out = {}
    for node in cls_node.body:
        if isinstance(node, ast.FunctionDef):
            out.setdefault(node.name, node)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out[node.target.id] = node
    return out


def test_class_members_match(stub):
    classes = {n: node for n, node in stub_top_level(stub).items() if isinstance(node, ast.ClassDef) and public(n)}
    assert len(classes) >= 20
    for name, node in classes.items():
        cls = getattr(vmap, name)
        if issubclass(cls, BaseException):
            continue
        declared = members(node)
        have = {m for m in dir(cls) if public(m)}
        stubbed = {m for m in declared if public(m)}
        assert have - stubbed == set(), f"{name}: members without a stub"
        assert stubbed - have == set(), f"{name}: stubs without a member"
        for dunder in {m for m in declared if m in PROTOCOL}:
            assert hasattr(cls, dunder), f"{name}.{dunder} is stubbed but the class has none"
        for dunder in PROTOCOL - {"__init__"}:
            if dunder in cls.__dict__:
                assert dunder in declared, f"{name}.{dunder} exists but has no stub"


def parse_signature(doc):
    """Parameter names, and the index of the keyword-only marker, from pybind11's first
    docstring line "name(a: T, *, b: U = d) -> R"; None for an overloaded function."""
    first = (doc or "").splitlines()[0] if doc else ""
    if "(" not in first or first.startswith("Overloaded"):
        return None
    inner = first[first.index("(") + 1:]
    depth, current, params = 0, "", []
    for ch in inner:
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            if depth == 0:
                break
            depth -= 1
        if ch == "," and depth == 0:
            params.append(current.strip())
            current = ""
        else:
            current += ch
    if current.strip():
        params.append(current.strip())
    return [p.split(":")[0].split("=")[0].strip() for p in params]


def stub_params(fn):
    a = fn.args
    names = [x.arg for x in a.posonlyargs + a.args]
    if a.vararg:
        names.append("*" + a.vararg.arg)
    elif a.kwonlyargs:
        names.append("*")
    names += [x.arg for x in a.kwonlyargs]
    return names


def check_params(qualname, compiled, node, is_method):
    got = parse_signature(compiled.__doc__)
    if got is None:
        return 0
    want = stub_params(node)
    if is_method and not isinstance(compiled, staticmethod):
        got = got[1:]  # self
        want = want[1:] if want and want[0] in ("self", "cls") else want
    assert got == want, f"{qualname}: module {got} != stub {want}"
    return 1


def test_parameters_match(stub):
    checked = 0
    for name, node in stub_top_level(stub).items():
        if not public(name):
            continue
        if isinstance(node, ast.FunctionDef):
            checked += check_params(name, getattr(vmap, name), node, False)
        elif isinstance(node, ast.ClassDef):
            cls = getattr(vmap, name)
            if issubclass(cls, BaseException):
                continue
            for member, m in members(node).items():
                if not isinstance(m, ast.FunctionDef) or (not public(member) and member != "__init__"):
                    continue
                raw = inspect.getattr_static(cls, member)
                static = isinstance(raw, staticmethod)
                compiled = getattr(cls, member)
                if isinstance(compiled, property):
                    continue
                got = parse_signature(compiled.__doc__)
                if got is None:
                    continue
                want = stub_params(m)
                if not static:
                    got, want = got[1:], [p for p in want if p not in ("self",)]
                assert got == want, f"{name}.{member}: module {got} != stub {want}"
                checked += 1
    assert checked >= 40
