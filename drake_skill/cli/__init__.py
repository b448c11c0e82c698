"""``drake-skill``, the command line: one argparse tree (``main``) whose
subcommands live beside it (``station_demo``, ``demos``, ``fit``, ...)."""
