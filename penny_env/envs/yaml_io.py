"""YAML reading with the numbers people write: PyYAML follows YAML 1.1, where ``1e-2`` (no dot) is a string,
not a float, so ``control_dt: 1e-2`` in a scene file failed with "must be a number, got '1e-2'". The
loader here is PyYAML's safe loader with YAML 1.2's float rule (``1e-2``, ``3E5``, ``.5``, ``-1.5e+3``); every
other value reads as PyYAML reads it, with these refusals: a key given twice in one mapping (PyYAML keeps
the last one silently: a second ``env_id`` won), nesting deeper than MAX_DEPTH (100,000 levels were a bare
RecursionError), aliases that expand to more than MAX_VALUES values (a 364-byte "billion laughs" file took minutes)
and a value that contains itself, all as yaml.YAMLError, which every caller reports as invalid YAML naming the file.
:func:`read_text` reads a config file with errors that name it (a folder, a missing file, bytes that are not
UTF-8)."""
from __future__ import annotations

import re

_FLOAT = re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                        |[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\.[0-9_]*
                        |[-+]?\.(?:inf|Inf|INF)
                        |\.(?:nan|NaN|NAN))$""", re.X)
_LOADER = []
MAX_DEPTH = 64  # nesting levels of a config: deeper is no configuration, and recursive code downstream would fail
# values of a config with its aliases expanded (the largest preset, envs.yaml, holds about 220): more is no
# configuration, and code downstream that copies or prints it (json.dumps) would expand every alias
MAX_VALUES = 100_000


def loader():
    """yaml.SafeLoader with YAML 1.2's floats (built once)."""
    if not _LOADER:
        import yaml

        class Loader(yaml.SafeLoader):
            def construct_mapping(self, node, deep=False):
                _refuse_duplicate_keys(self, node)
                return super().construct_mapping(node, deep)

        # replace the float resolver (YAML 1.1's needs a dot) for the characters a float may start with
        Loader.yaml_implicit_resolvers = {k: [(tag, rx) for tag, rx in v if tag != "tag:yaml.org,2002:float"]
                                          for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
        Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))
        _LOADER.append(Loader)
    return _LOADER[0]


def _refuse_duplicate_keys(constructor, node) -> None:
    """yaml's ConstructorError where a mapping gives a key twice (merge keys ``<<`` excepted: explicit keys
    override merged ones)."""
    import yaml
    seen = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = constructor.construct_object(key_node, deep=True)
        try:
            first = seen.setdefault(key, key_node.start_mark)
        except TypeError:  # an unhashable key: PyYAML's own error follows
            continue
        if first is not key_node.start_mark:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark,
                f"found the key {key!r} twice (first on line {first.line + 1}); give each key once", key_node.start_mark)


def _nesting_error(levels: str):
    import yaml
    return yaml.YAMLError(f"nested {levels} levels deep; a configuration nests at most {MAX_DEPTH} levels")


def _shape(data) -> tuple[int, int]:
    """(nesting depth, number of values with the aliases expanded) of the lists and dicts in ``data``, each container
    visited once: aliases share their lists and dicts, so a walk of the expanded tree ("billion laughs": 364 bytes of
    nine levels of nine aliases, 4.3e8 values) took minutes, while this one takes the file's own size. yaml.YAMLError
    for a list or dict inside itself (an alias to a container it is in)."""
    import yaml
    memo: dict = {}      # id of a finished container -> (its depth, its expanded count)
    path: set = set()    # ids of the containers being walked (the current one's ancestors)
    containers = (list, dict)
    if not isinstance(data, containers):
        return 0, 0
    stack = [(data, False)]
    while stack:
        value, finished = stack.pop()
        key = id(value)
        inner = [v for v in (value.values() if isinstance(value, dict) else value) if isinstance(v, containers)]
        if finished:
            memo[key] = (1 + max((memo[id(v)][0] for v in inner), default=0),
                         len(value) + sum(memo[id(v)][1] for v in inner))
            path.discard(key)
            continue
        if key in memo:
            continue
        path.add(key)
        stack.append((value, True))
        for v in inner:
            if id(v) in path:
                raise yaml.YAMLError("an alias refers to a list or mapping that contains it (a recursive value); a "
                                     "configuration is a tree")
            if id(v) not in memo:
                stack.append((v, False))
    return memo[id(data)]


def safe_load(stream):
    """yaml.safe_load with 1e-2 read as a float, a key given twice, nesting deeper than MAX_DEPTH, aliases that expand
    to more than MAX_VALUES values and recursive values refused as yaml.YAMLError (the module docstring)."""
    import yaml
    try:
        data = yaml.load(stream, Loader=loader())  # noqa: S506 (a SafeLoader subclass)
    except RecursionError:
        raise _nesting_error("thousands of") from None
    depth, values = _shape(data)
    if depth > MAX_DEPTH:
        raise _nesting_error(f"more than {MAX_DEPTH}")
    if values > MAX_VALUES:
        raise yaml.YAMLError(f"its aliases expand to {values} values; a configuration holds at most {MAX_VALUES} (a "
                             "file of nested aliases, \"billion laughs\", would take any reader minutes and gigabytes)")
    return data


def read_text(path, what: str = "config file") -> str:
    """The text of a UTF-8 file; ValueError naming ``what`` and the path for a missing file, a folder, an unreadable
    file, or bytes that are not UTF-8 (they were a bare FileNotFoundError, IsADirectoryError, UnicodeDecodeError)."""
    from pathlib import Path
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{what} {path} is a folder, not a YAML file")
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ValueError(f"{what} {path}: no such file") from None
    except OSError as exc:
        raise ValueError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise ValueError(f"{what} {path} is not UTF-8 text (byte 0x{raw[exc.start]:02x} on line {line}); save it as "
                         "UTF-8") from None
