"""Options shared by several commands, defined once."""

from __future__ import annotations

from pathlib import Path

import click

overwrite_option = click.option(
    "--overwrite", is_flag=True, help="Replace existing outputs (refused otherwise).")
json_option = click.option(
    "--json", "as_json", is_flag=True, help="Machine-readable JSON on stdout.")
seed_option = click.option("--seed", type=int, default=0, show_default=True,
                           help="Random seed (same seed, byte-identical output).")


def check_output_file(path: Path, overwrite: bool) -> None:
    """Refuse to replace an existing output unless ``--overwrite`` was given."""
    if path.exists() and not overwrite:
        raise click.ClickException(f"{path}: already exists (use --overwrite to replace it)")


def progress_enabled() -> bool:
    """Progress bars only on an interactive stderr."""
    import sys

    return sys.stderr.isatty()
