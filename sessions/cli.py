"""The ``vascsim`` command line."""

import click


@click.group()
def main() -> None:
    """vascsim: haptic vascular-suturing simulator and assessment platform."""
