"""Command-line interface (work in progress)."""


def main(argv=None):
    raise SystemExit("pamid: the command-line interface is being written")
