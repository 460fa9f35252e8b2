"""How a world named on the command line is found: the ``gym:`` prefix of Gymnasium worlds, and the
import of a user's module named in ``gym:module:ENV_ID`` or ``package.module:Class``.

Both the registry and the Gymnasium world import this module (neither imports the other at load).
"""

from __future__ import annotations

import importlib
import os
import sys
from types import ModuleType

GYM_PREFIX = "gym:"


def import_user_module(module: str) -> ModuleType:
    """Import `module` as ``python -m`` would from here: when it is not on the import path, the
    current directory is added (at the end, so that it shadows no installed package) and the import
    retried. An ImportError that remains says where it looked and how to point elsewhere."""
    top = module.partition(".")[0]
    cwd = os.getcwd()
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as e:
        if e.name != top:
            raise  # the module was found; something it imports was not
    if cwd not in sys.path and "" not in sys.path:
        sys.path.append(cwd)
        try:
            return importlib.import_module(module)
        except ModuleNotFoundError as e:
            if e.name != top:
                raise
    raise ModuleNotFoundError(
        f"No module named {top!r} in the current directory ({cwd}) or on the Python path: run from the folder "
        f"that holds {top}.py (or its package), or add that folder to PYTHONPATH",
        name=top,
    )
