"""The ``fusion-vo`` command line: one thin module per sub-command, registered in :mod:`.main`."""
