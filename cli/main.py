"""Entry point of the ``posegraph`` command."""

from __future__ import annotations

import argparse
import sys

import posegraph


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="posegraph", description=posegraph.__doc__)
    parser.add_argument("--version", action="version", version=f"posegraph {posegraph.__version__}")
    return parser


def main(argv: list[str] | None = None) -> int:
    build_parser().parse_args(argv)
    return 0


if __name__ == "__main__":
    sys.exit(main())
