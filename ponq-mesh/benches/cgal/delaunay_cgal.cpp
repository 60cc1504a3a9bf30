// CGAL reference timing for `delaunay_bench` (not part of the Rust build; CGAL is GPL/LGPL and
// only used here, as an external yardstick on the same machine and the same points).
// Reads raw little-endian f64 x,y,z triples, inserts them with CGAL's range insert (spatial
// sort + remembering walk, Exact_predicates_inexact_constructions_kernel, one thread) and
// prints the best of R runs: "<file> <points> <finite cells> <best ms> <us/point>".
// Build: g++ -O3 -DNDEBUG delaunay_cgal.cpp -o delaunay_cgal -lgmp -lmpfr
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Delaunay_triangulation_3.h>
#include <chrono>
#include <cstdio>
#include <vector>

#include "read_points.h"

typedef CGAL::Exact_predicates_inexact_constructions_kernel K;
typedef CGAL::Delaunay_triangulation_3<K> DT;

int main(int argc, char** argv) {
  int reps = 5;
  for (int a = 1; a < argc; ++a) {
    std::vector<double> xyz;
    if (!read_points(argv[a], xyz)) return 1;
    std::vector<K::Point_3> pts;
    for (size_t i = 0; i + 2 < xyz.size(); i += 3) pts.emplace_back(xyz[i], xyz[i + 1], xyz[i + 2]);
    double best = 1e30;
    size_t cells = 0;
    for (int r = 0; r < reps; ++r) {
      auto t0 = std::chrono::steady_clock::now();
      DT dt(pts.begin(), pts.end());
      double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      if (ms < best) best = ms;
      cells = dt.number_of_finite_cells();
    }
    std::printf("%s %zu %zu %.1f %.2f\n", argv[a], pts.size(), cells, best, best * 1e3 / pts.size());
  }
  return 0;
}
