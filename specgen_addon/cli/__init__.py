"""SpecGen core: cli (see docs/dev/architecture.md)."""

__all__ = ["main"]


def __getattr__(name: str):
    # lazily: the entry point (cli/entry.py) loads the commands inside its own Ctrl-C guard
    if name == "main":
        from specgen_addon.cli.app import main

        return main
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
