"""Maps built from the frames: the object map now; the object experience map and its back ends later."""
