"""The `neoslam` console script and `python -m neoslam`: stop signals handled from the first line (see
neoslam.stopping), then the command line, whose imports take a second or more."""

from __future__ import annotations

from neoslam import stopping


def main() -> None:
    stopping.install()
    from neoslam.cli import entry

    entry()


if __name__ == "__main__":
    main()
