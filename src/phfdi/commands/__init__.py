"""Subcommands of ``phfdi``; see :mod:`phfdi.cli`."""
