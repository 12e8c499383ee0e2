"""Adapters for trainers outside the package, one module each.

None is imported here: each module imports its trainer (``uasep_env.clients.omnisafe``
imports OmniSafe), and the package imports without any of them.
"""
