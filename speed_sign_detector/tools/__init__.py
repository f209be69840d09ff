"""Command-line programs; each module has ``main(argv: list[str] | None) -> int``."""
