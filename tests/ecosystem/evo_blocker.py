"""Source of a preamble that makes ``import evo`` fail, for scripts run in a fresh interpreter
(``python -c BLOCK_EVO + script``): the core must work without the ``eval`` extra."""

import textwrap

BLOCK_EVO = textwrap.dedent("""
    import importlib.abc, sys

    class BlockEvo(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name == "evo" or name.startswith("evo."):
                raise ImportError("evo is blocked")
            return None

    sys.meta_path.insert(0, BlockEvo())
""")
