"""The ``quadloc`` command line: a thin front end of the application (``quadloc.service.app``)
and of the SDK (``--url``). The parser and the dispatch: :mod:`quadloc.service.cli.main`."""
