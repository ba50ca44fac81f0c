"""Pure computation: characters, kinematics, dynamics, estimation and optimization.

Never imports web, queue, database or settings code.
"""
