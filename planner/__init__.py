"""The ``rapt-plan`` command line: it wires :mod:`rapt`, :mod:`sim` and :mod:`bridge` together."""
