"""``motionx`` subcommands. Each module exposes ``register(subparsers)``.

Add a module to ``MODULES`` to add its commands; keep argument parsing and printing here
and the work in ``solver``/``mjcf``.
"""

MODULES = [
    "service.commands.physics",
    "service.commands.tutor",
    "service.commands.demo",
    "service.commands.export",
    "service.commands.serve",
    "service.commands.grf",
    "service.commands.plot",
]
