"""Synthetic systems under test whose performance boundaries are known exactly.

A real simulation never tells us where its performance boundaries are, so search
quality (precision, coverage, convergence; section 3.6.2 of the dissertation) can only
be measured on stand-ins whose boundaries are known *a priori*.  This package builds
those stand-ins, one family per module:

* :mod:`~rapt.testfunctions.base` - the interface every system implements;
* :mod:`~rapt.testfunctions.geometry` - exact signed distances to the shapes used;
* :mod:`~rapt.testfunctions.shapes` - the Custom2D, Plates2D and Plates3D functions of
  section 3.6.1 (and Rings2D);
* :mod:`~rapt.testfunctions.composites` - the screened 7-D and composite 8-D systems of
  section 3.6.3;
* :mod:`~rapt.testfunctions.noise` - the fuzzy-boundary and global-error noise models of
  sections 4.2.1-4.2.2;
* :mod:`~rapt.testfunctions.hierarchical` - score trees of section 4.3.2;
* :mod:`~rapt.testfunctions.registry` - the benchmarked systems by name, with their
  budgets and boundary widths.

Only numpy is used (scipy for Hierarchical2D's distances); every evaluation is vectorised
(10^6 points in well under a second for the 2-D and 3-D systems).
"""
