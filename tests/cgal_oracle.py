"""Test oracle: CGAL's ``Surface_mesh_deformation`` run from a small C++ driver.

Used by ``tests/test_methods.py`` and ``benchmarks/cgal_agreement.py``. The driver is built
once per session when the CGAL and Eigen 3 headers and a C++ compiler are installed
(``apt-get install g++ libcgal-dev libeigen3-dev``); :func:`build_driver` returns the reason
otherwise.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np

CGAL_DRIVER = r"""
// CGAL's Surface_mesh_deformation with given handles and, optionally, a region of interest.
// usage: driver MESH.off HANDLES.txt ("vertex x y z" lines) TAG ALPHA ITERATIONS TOL OUT.txt
//               [ROI.txt (vertex ids; without it the ROI is the whole mesh)]
// TAG: sre (SRE_ARAP), rims (SPOKES_AND_RIMS), arap (ORIGINAL_ARAP)
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_deformation.h>
#include <fstream>
#include <string>
#include <vector>

typedef CGAL::Simple_cartesian<double> K;
typedef CGAL::Surface_mesh<K::Point_3> Mesh;
typedef boost::graph_traits<Mesh>::vertex_descriptor VD;

template <CGAL::Deformation_algorithm_tag TAG>
int run(Mesh& m, const std::vector<int>& h, const std::vector<K::Point_3>& t,
        const std::vector<int>* roi, double alpha, unsigned iters, double tol) {
  CGAL::Surface_mesh_deformation<Mesh, CGAL::Default, CGAL::Default, TAG> d(m);
  if (roi) {
    for (int i : *roi) d.insert_roi_vertex(VD(i));
  } else {
    d.insert_roi_vertices(vertices(m).begin(), vertices(m).end());
  }
  for (int i : h) d.insert_control_vertex(VD(i));
  if (!d.preprocess()) return 3;
  for (std::size_t i = 0; i < h.size(); ++i) d.set_target_position(VD(h[i]), t[i]);
  d.set_sre_arap_alpha(alpha);
  d.deform(iters, tol);
  return 0;
}

int main(int argc, char** argv) {
  if (argc != 8 && argc != 9) return 2;
  Mesh m;
  std::ifstream in(argv[1]);
  if (!(in >> m)) return 4;
  std::ifstream hf(argv[2]);
  std::vector<int> h;
  std::vector<K::Point_3> t;
  int v;
  double x, y, z;
  while (hf >> v >> x >> y >> z) { h.push_back(v); t.emplace_back(x, y, z); }
  std::vector<int> roi;
  if (argc == 9) {
    std::ifstream rf(argv[8]);
    while (rf >> v) roi.push_back(v);
  }
  const std::vector<int>* r = argc == 9 ? &roi : nullptr;
  std::string tag = argv[3];
  double alpha = std::stod(argv[4]);
  unsigned iters = std::stoul(argv[5]);
  double tol = std::stod(argv[6]);
  int rc = tag == "sre"    ? run<CGAL::SRE_ARAP>(m, h, t, r, alpha, iters, tol)
           : tag == "arap" ? run<CGAL::ORIGINAL_ARAP>(m, h, t, r, alpha, iters, tol)
                           : run<CGAL::SPOKES_AND_RIMS>(m, h, t, r, alpha, iters, tol);
  if (rc) return rc;
  std::ofstream out(argv[7]);
  out.precision(17);
  for (VD vd : vertices(m)) out << m.point(vd) << "\n";
  return 0;
}
"""


def build_driver(directory: Path) -> Path | str:
    """Compile the driver into ``directory``; its path, or why it cannot be built."""
    if not Path("/usr/include/CGAL/Surface_mesh_deformation.h").exists():
        return "CGAL headers not installed (apt-get install libcgal-dev libeigen3-dev)"
    if not Path("/usr/include/eigen3").exists():
        return "Eigen 3 headers not installed (apt-get install libeigen3-dev)"
    cxx = shutil.which(os.environ.get("CXX", "g++"))
    if cxx is None:
        return "no C++ compiler to build the CGAL oracle"
    (directory / "driver.cpp").write_text(CGAL_DRIVER)
    subprocess.run([cxx, "-O1", "-std=c++17", "-DCGAL_EIGEN3_ENABLED", "-I/usr/include/eigen3",
                    str(directory / "driver.cpp"), "-o", str(directory / "driver")],
                   check=True, timeout=900, capture_output=True)
    return directory / "driver"


def run_cgal(driver: Path, mesh_path: Path, h, T, tag: str, alpha: float, tmp: Path,
             roi=None, iterations: int = 5000, tol: float = 1e-13) -> np.ndarray:
    """Deform ``mesh_path`` (an OFF file) with CGAL; the vertex positions after.

    ``h``, ``T``: control vertices and their targets. ``roi``: the region of interest's
    vertex ids (the control vertices are added to it); None for the whole mesh.
    """
    np.savetxt(tmp / "h.txt", np.column_stack([h, T]), fmt=["%d", "%.17g", "%.17g", "%.17g"])
    out = tmp / f"out_{tag}.txt"
    args = [str(driver), str(mesh_path), str(tmp / "h.txt"), tag, repr(alpha),
            str(iterations), repr(tol), str(out)]
    if roi is not None:
        np.savetxt(tmp / "roi.txt", np.asarray(roi, dtype=np.int64), fmt="%d")
        args.append(str(tmp / "roi.txt"))
    subprocess.run(args, check=True, timeout=600)
    return np.loadtxt(out)
