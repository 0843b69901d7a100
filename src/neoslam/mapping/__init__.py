"""Maps built from the frames: the object experience map and its back ends, the object map, moving objects."""
