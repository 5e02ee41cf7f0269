"""The CLI's subcommands: each module exposes ``register(subparsers)``.

``register`` adds one subparser and sets its ``func`` default to a callable taking the parsed
arguments and returning an exit code. Heavy imports happen inside ``func``, never at import time,
so ``onionsort --help`` stays fast.
"""

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
    "onionsort.commands.learn",
    "onionsort.commands.evaluate",
    "onionsort.commands.score",
    "onionsort.commands.suggest",
    "onionsort.commands.demo",
    "onionsort.commands.report",
]


def add_command(subparsers, name: str, doc: str | None, help_: str, config_cls, run):
    """Add the subparser ``name``, whose description is the command module's docstring
    ``doc`` (none for a command's model or action) and whose options are the
    :func:`~onionsort.configs.option` fields of ``config_cls``; ``run(args)`` runs it.
    Returns the subparser, whose ``config_class`` is ``config_cls`` (for the tests and the
    docs)."""
    import argparse

    from onionsort.configs import add_config_arguments

    parser = subparsers.add_parser(name, help=help_, description=doc,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    add_config_arguments(parser, config_cls)
    parser.set_defaults(func=run)
    parser.config_class = config_cls
    return parser
