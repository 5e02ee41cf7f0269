"""The CLI's subcommands: each module exposes ``register(subparsers)``.

``register`` adds one subparser and sets its ``func`` default to a callable taking the parsed
arguments and returning an exit code. Heavy imports happen inside ``func``, never at import time,
so ``onionsort --help`` stays fast.

Every command and subcommand has a description that ends with a numpydoc ``Examples`` section
of runnable command lines (a command module's docstring, or a subcommand's own text), and
every option a help that ends with its default (:mod:`onionsort.configs`);
tests/test_cli_help.py checks both over the whole parser.
"""

import re

COMMAND_MODULES = [
    "onionsort.commands.experiment",
    "onionsort.commands.record",
    "onionsort.commands.import_video",
    "onionsort.commands.export",
    "onionsort.commands.dataset",
    "onionsort.commands.label",
    "onionsort.commands.train",
    "onionsort.commands.perceive",
    "onionsort.commands.calibrate",
    "onionsort.commands.eval_perception",
    "onionsort.commands.compare_perception",
    "onionsort.commands.eval_posterior",
    "onionsort.commands.learn",
    "onionsort.commands.evaluate",
    "onionsort.commands.score",
    "onionsort.commands.suggest",
    "onionsort.commands.demo",
    "onionsort.commands.report",
]


def plain(doc: str | None) -> str | None:
    """A docstring as a terminal shows it: its reStructuredText literals and roles
    (````x````, ``:mod:`x```) as `x`."""
    if doc is None:
        return None
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"`\1`", doc)
    return re.sub(r"``(.+?)``", r"`\1`", text, flags=re.S)


def add_group(subparsers, name: str, doc: str, help_: str, *, dest: str, metavar: str):
    """Add the subparser ``name`` of a command with subcommands of its own (``train MODEL``,
    ``label ACTION``), described by ``doc``; returns the subparsers to add them to, whose
    choice is parsed into ``dest``."""
    import argparse

    parser = subparsers.add_parser(name, help=help_, description=plain(doc),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    return parser.add_subparsers(dest=dest, metavar=metavar, required=True)


def add_command(subparsers, name: str, doc: str | None, help_: str, config_cls, run):
    """Add the subparser ``name``, whose description is ``doc`` (the command module's
    docstring, or a subcommand's own text, each ending with numpydoc ``Examples``) and whose
    options are the :func:`~onionsort.configs.option` fields of ``config_cls``; ``run(args)``
    runs it. Returns the subparser, whose ``config_class`` is ``config_cls`` (for the tests
    and the docs)."""
    import argparse

    from onionsort.configs import add_config_arguments

    parser = subparsers.add_parser(name, help=help_, description=plain(doc),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    add_config_arguments(parser, config_cls)
    parser.set_defaults(func=run)
    parser.config_class = config_cls
    return parser
