"""Options shared by several commands, defined once."""

from __future__ import annotations

from pathlib import Path

import click

overwrite_option = click.option(
    "--overwrite", is_flag=True, help="Replace existing outputs (refused otherwise).")
json_option = click.option(
    "--json", "as_json", is_flag=True, help="Machine-readable JSON on stdout.")
fit_workers_option = click.option(
    "--workers", type=click.IntRange(min=1), default=None,
    help="Processes for the seed fits (default: one per core, at most 8; the map is the same "
         "for any number).")
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


def B_option(default: float | None = 0.02):  # noqa: N802 - B is the paper's name
    """``--B``: smallest expected surface curvature radius [m]; required when ``default`` is
    None (click treats an explicit ``default=None`` as a value, so it is not passed)."""
    given = {"default": default, "show_default": True} if default is not None else {}
    return click.option(
        "--B", "B", type=click.FloatRange(min=0.0, min_open=True), required=default is None,
        help="Smallest expected surface curvature radius B [m].", **given)


robot_option = click.option(
    "--robot", "robot_file", type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None, help="URDF file (default: the log's /robot_description).")
joint_topic_option = click.option(
    "--joint-topic", default=None, help="JointState topic (default: /joint_states).")
command_topic_option = click.option(
    "--command-topic", default=None,
    help="Commanded torques topic (JointState effort or Float64MultiArray).")


def prepare_output_dir(path: Path, names: list[str], overwrite: bool) -> None:
    """Refuse when any of ``names`` already exists in ``path`` unless overwriting, or when
    ``path`` is not a folder.  The folder itself is created by the writer, after the work
    succeeded, so a failed command leaves nothing behind."""
    if path.exists() and not path.is_dir():
        raise click.ClickException(f"{path}: exists and is not a folder")
    existing = [n for n in names if (path / n).exists()]
    if existing and not overwrite:
        raise click.ClickException(
            f"{path}: already holds {', '.join(existing)} (use --overwrite to replace)")


causal_option = click.option(
    "--causal", is_flag=True,
    help="Classify with the swept map as the robot saw it at each contact (default: whole run).")
loss_option = click.option(
    "--loss", type=click.Choice(["linear", "huber", "cauchy"]), default="huber",
    show_default=True, help="Fit loss (robust losses resist misclassified contacts).")
