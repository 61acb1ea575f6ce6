"""The ``kinfw`` command line (:func:`main`; ``python -m kinfw.cli`` runs it too), its
table of commands (:data:`COMMANDS`: a new command is a module and one entry there) and
:func:`register_command`, which adds a command from outside (a plugin's:
:mod:`kinfw.plugins`).

The only layer of kinfw that imports :mod:`kinfw.identification` and
:mod:`kinfw.verification`. Each command is a thin layer over the library's verbs: it
parses arguments, checks the outputs before any work, calls the verb and prints. Start-up
imports only the standard library, so ``kinfw --help`` is immediate.
"""

from kinfw.cli._main import COMMANDS, main, register_command

__all__ = ["COMMANDS", "main", "register_command"]
