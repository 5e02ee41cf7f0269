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
    "onionsort.commands.suggest",
    "onionsort.commands.demo",
    "onionsort.commands.report",
]
