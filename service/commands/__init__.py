"""``motionx`` subcommands. Each module exposes ``register(subparsers)``.

Add a module to ``MODULES`` to add its commands; keep argument parsing and printing here
and the work in ``solver``/``mjcf``.

Command modules import the solver inside their command functions, on purpose: building the
parser imports every module listed here, so a module-level solver import would make every
``motionx`` call, ``--help`` included, load numpy, SciPy or CasADi first (``--help``: 0.7 s).
"""

MODULES = [  # the order of the command list: the main job first
    "service.commands.tutor",  # tutor, extrapolate, validate
    "service.commands.plot",
    "service.commands.export",
    "service.commands.library",
    "service.commands.demo",
    "service.commands.grf",  # grf, grf-compare
    "service.commands.physics",  # mjcf, check-dynamics
    "service.commands.simulate",
    "service.commands.serve",  # serve, stack, db, apikey, openapi
    "worker.command",  # worker (named, not imported: service/ never imports worker/)
]
