"""The `drivestack` entry point, also `python -m stack`: SIGINT and SIGTERM are held from its first
line, so a stop while the command line is imported ends the command with exit 130 before any work
(`stack.runtime.interrupts.hold_signals`)."""

from stack.runtime.interrupts import hold_signals


def main() -> None:
    """Hold signals, then run the CLI (`stack.apps.cli.main`)."""
    hold_signals()
    from stack.apps.cli import main as cli

    cli()


if __name__ == "__main__":
    main()
