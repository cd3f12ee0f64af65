"""SpecGen core: cli (see docs/dev/architecture.md)."""

from specgen_addon.cli.app import main

__all__ = ["main"]
