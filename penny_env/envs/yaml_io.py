"""YAML reading with the numbers people write: PyYAML follows YAML 1.1, where ``1e-2`` (no dot) is a string,
not a float, so ``control_dt: 1e-2`` in a scene file failed with "must be a number, got '1e-2'". The
loader here is PyYAML's safe loader with YAML 1.2's float rule (``1e-2``, ``3E5``, ``.5``, ``-1.5e+3``); every
other value reads as PyYAML reads it."""
from __future__ import annotations

import re

_FLOAT = re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                        |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
                        |[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\.[0-9_]*
                        |[-+]?\.(?:inf|Inf|INF)
                        |\.(?:nan|NaN|NAN))$""", re.X)
_LOADER = []


def loader():
    """yaml.SafeLoader with YAML 1.2's floats (built once)."""
    if not _LOADER:
        import yaml

        class Loader(yaml.SafeLoader):
            pass

        # replace the float resolver (YAML 1.1's needs a dot) for the characters a float may start with
        Loader.yaml_implicit_resolvers = {k: [(tag, rx) for tag, rx in v if tag != "tag:yaml.org,2002:float"]
                                          for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
        Loader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT, list("-+0123456789."))
        _LOADER.append(Loader)
    return _LOADER[0]


def safe_load(stream):
    """yaml.safe_load with 1e-2 read as a float (the module docstring)."""
    import yaml
    return yaml.load(stream, Loader=loader())  # noqa: S506 (a SafeLoader subclass)
