// HXT reference timing for `delaunay_bench` (not part of the Rust build; gmsh is GPL and only
// used here, as an external yardstick on the same machine and the same points). HXT is the
// parallel Delaunay of Marot, Pellerin and Remacle (2019), shipped inside gmsh; gmsh's API
// `gmsh::model::mesh::tetrahedralize` runs it when `Mesh.Algorithm3D` is 10.
// Reads raw little-endian f64 x,y,z triples and prints the best of R runs, once per thread
// count given: "<file> <threads> <points> <tets> <best ms> <us/point>".
// The time includes gmsh's conversion of the points to its vertex objects and of HXT's tets
// back to gmsh's (allocations of one object per point and per tet), so it is an upper bound
// of HXT's own time (perf attributes about 77% of it to HXT on random points, README);
// `HXT_VERBOSE=1` prints gmsh's log.
// Build: g++ -O3 -DNDEBUG delaunay_hxt.cpp -o delaunay_hxt -lgmsh
#include <gmsh.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "../cgal/read_points.h"

int main(int argc, char** argv) {
  const int reps = 5;
  const int thread_counts[] = {1, 2};
  gmsh::initialize();
  gmsh::option::setNumber("General.Terminal", std::getenv("HXT_VERBOSE") ? 1 : 0);
  gmsh::option::setNumber("General.Verbosity", std::getenv("HXT_VERBOSE") ? 99 : 0);
  gmsh::option::setNumber("Mesh.Algorithm3D", 10);
  for (int a = 1; a < argc; ++a) {
    std::vector<double> xyz;
    if (!read_points(argv[a], xyz)) return 1;
    for (int threads : thread_counts) {
      gmsh::option::setNumber("General.NumThreads", threads);
      gmsh::option::setNumber("Mesh.MaxNumThreads3D", threads);
      double best = 1e30;
      size_t tets = 0;
      for (int r = 0; r < reps; ++r) {
        std::vector<std::size_t> tetra;
        auto t0 = std::chrono::steady_clock::now();
        gmsh::model::mesh::tetrahedralize(xyz, tetra);
        double ms =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
        if (ms < best) best = ms;
        tets = tetra.size() / 4;
      }
      size_t n = xyz.size() / 3;
      std::printf("%s %d %zu %zu %.1f %.2f\n", argv[a], threads, n, tets, best, best * 1e3 / n);
    }
  }
  gmsh::finalize();
  return 0;
}
