//! File formats: PoNQ `.npz` files and triangle meshes (OBJ, PLY, OFF, STL).
