// The point files of `delaunay_bench --write`: raw little-endian f64 x, y, z triples.
// Shared by the external yardsticks (delaunay_cgal.cpp, ../hxt/delaunay_hxt.cpp).
#pragma once
#include <cstdio>
#include <fstream>
#include <vector>

// The coordinates of `path`, a whole number of triples (a trailing partial one is dropped);
// prints an error and returns false when the file cannot be read.
inline bool read_points(const char* path, std::vector<double>& xyz) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) {
    std::fprintf(stderr, "cannot read %s\n", path);
    return false;
  }
  size_t bytes = in.tellg();
  xyz.assign(bytes / sizeof(double), 0.0);
  in.seekg(0);
  in.read(reinterpret_cast<char*>(xyz.data()), bytes);
  xyz.resize(xyz.size() / 3 * 3);
  return true;
}
