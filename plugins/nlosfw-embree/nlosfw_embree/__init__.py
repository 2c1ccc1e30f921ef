"""nlosfw-embree: a ray-traced three-bounce transient simulator built on Embree (embreex).

Importing this package is light; ``embreex`` is imported by
:mod:`nlosfw_embree.simulator` only, when the simulator is first created.
"""

__version__ = "0.1.0"
