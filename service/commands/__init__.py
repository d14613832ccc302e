"""The service's own ``orbitcal`` sub-commands: ``serve``, ``worker`` and ``demo``.

The library never imports the service (STYLE: "the service imports the library, never the
reverse"), so these commands register themselves with ``orbitcal.cli`` through the entry-point
group ``orbitcal.commands`` declared in ``pyproject.toml``: each entry names a
``register(subparsers)`` function, exactly like the library's own command modules.
"""
