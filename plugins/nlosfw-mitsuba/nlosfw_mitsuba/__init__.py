"""nlosfw-mitsuba: transient rendering with Mitsuba 3 and mitransient.

Importing this package is light; mitsuba, drjit and mitransient are imported
by :mod:`nlosfw_mitsuba.simulator` only when a simulator renders, after
:func:`nlosfw_mitsuba.llvm.configure_llvm` has pointed Dr.Jit at a working LLVM.
"""

__version__ = "0.1.0"
