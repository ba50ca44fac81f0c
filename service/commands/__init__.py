"""``motionx`` subcommands. Each module exposes ``register(subparsers)``.

Add a module to ``MODULES`` to add its commands; keep argument parsing and printing here
and the work in ``solver``/``mjcf``.
"""

MODULES = [  # the order of the command list: the main job first
    "service.commands.tutor",  # tutor, extrapolate, validate
    "service.commands.plot",
    "service.commands.export",
    "service.commands.library",
    "service.commands.demo",
    "service.commands.grf",  # grf, grf-compare
    "service.commands.physics",  # mjcf, check-dynamics
    "service.commands.serve",  # serve, stack, db, apikey, openapi
    "worker.command",  # worker (named, not imported: service/ never imports worker/)
]
