"""SpecGen core: brdf (see docs/dev/architecture.md)."""
