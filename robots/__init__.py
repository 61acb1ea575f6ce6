"""The built-in robots' URDFs, installed as the data package ``kinfw.robots``: the IIS-head
of Shih et al. (1992), ``iis_head.urdf`` (:func:`kinfw.model.builtin_head_urdf` finds it)."""
