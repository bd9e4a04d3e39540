"""Studies: measurements of clothlab itself, not of cloth.

``clothlab bench`` (:mod:`clothlab.studies.bench`: the section list and the run loop, one module per section,
the shared timing harness :mod:`clothlab.studies.timing` and data source :mod:`clothlab.studies.data`) and
``clothlab check`` (:mod:`clothlab.studies.stability`, with the stiff fits of :mod:`clothlab.studies.stiff`).
Studies return their figures and human-readable lines; they never print, and read data only from the
directory they are given (or the example measurements they regenerate).
"""
