"""The 2D matching toolbox: point maps and normals, point-to-line ICP, likelihood fields, branch-and-bound search, scan descriptors."""
