#include "granmpm/output.hpp"

#include <hdf5.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "granmpm/scene.hpp"
#include "granmpm/simulation.hpp"
#include "h5util.hpp"

namespace granmpm {

using h5::write_box;
using h5::write_rows;
using H5Check = h5::Check;

template <int dim>
Output<dim>::Output(Simulation<dim> &sim) : sim_(sim) {
  // Fail at start-up, not hours later, if the output directory cannot be written.
  bool bad = false;
  std::string msg;
  if (sim.rank == 0) {
    std::error_code ec;
    std::filesystem::create_directories(sim.cfg.output_dir, ec);
    const std::string probe = sim.cfg.output_dir + "/.granmpm_write_test";
    std::FILE *f = std::fopen(probe.c_str(), "w");
    if (ec || !f) {
      bad = true;
      msg = "output directory '" + sim.cfg.output_dir + "' is not writable" + (ec ? " (" + ec.message() + ")" : std::string()) + "; change -output_dir";
    }
    if (f) {
      std::fclose(f);
      std::remove(probe.c_str());
    }
  }
  collective_fail(sim.comm, bad, msg);
}

template <int dim>
void Output<dim>::write(Scene<dim> &scene) {
  (void)scene;
  Simulation<dim> &S = sim_;
  char name[64];
  std::snprintf(name, sizeof name, "snap_%06d.h5", (int)frames_.size());
  const std::string path = S.cfg.output_dir + "/" + name, tmp = path + ".tmp";
  H5Check chk{path};
  hid_t file = h5::create(S.comm, tmp);
  int ok = file >= 0, all_ok = 0;
  MPI_Allreduce(&ok, &all_ok, 1, MPI_INT, MPI_MIN, S.comm);
  if (!all_ok) throw UserError("cannot create " + tmp + ": check -output_dir");

  // Particles.
  ParticleView<dim> P = S.particles.get();
  long n = P.n, off = 0, tot = 0;
  MPI_Exscan(&n, &off, 1, MPI_LONG, MPI_SUM, S.comm);
  if (S.rank == 0) off = 0;
  MPI_Allreduce(&n, &tot, 1, MPI_LONG, MPI_SUM, S.comm);
  hid_t grp = H5Gcreate2(file, "particles", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  std::vector<double> b3((size_t)n * 3), b1(n);
  auto vec3 = [&](const double *src) {
    for (long p = 0; p < n; ++p)
      for (int d = 0; d < 3; ++d) b3[p * 3 + d] = d < dim ? src[p * dim + d] : 0.0;
    return b3.data();
  };
  write_rows(file, "/particles/id", H5T_NATIVE_INT64, P.id, n, off, tot, 1, chk);
  write_rows(file, "/particles/position", H5T_NATIVE_DOUBLE, vec3(P.x), n, off, tot, 3, chk);
  write_rows(file, "/particles/velocity", H5T_NATIVE_DOUBLE, vec3(P.v), n, off, tot, 3, chk);
  write_rows(file, "/particles/mass", H5T_NATIVE_DOUBLE, P.m, n, off, tot, 1, chk);
  write_rows(file, "/particles/volume", H5T_NATIVE_DOUBLE, P.vol, n, off, tot, 1, chk);
  for (long p = 0; p < n; ++p) b1[p] = P.m[p] / P.vol[p];
  write_rows(file, "/particles/density", H5T_NATIVE_DOUBLE, b1.data(), n, off, tot, 1, chk);
  // Stress as XDMF Tensor6 order (xx, xy, xz, yy, yz, zz).
  std::vector<double> b6((size_t)n * 6);
  for (long p = 0; p < n; ++p) {
    const double *s = P.s + 6 * p;
    const double t[6] = {s[0], s[3], s[5], s[1], s[4], s[2]};
    for (int c = 0; c < 6; ++c) b6[p * 6 + c] = t[c];
  }
  write_rows(file, "/particles/stress", H5T_NATIVE_DOUBLE, b6.data(), n, off, tot, 6, chk);
  for (long p = 0; p < n; ++p) b1[p] = pressure6(P.s + 6 * p);
  write_rows(file, "/particles/pressure", H5T_NATIVE_DOUBLE, b1.data(), n, off, tot, 1, chk);
  for (long p = 0; p < n; ++p) b1[p] = tau6(P.s + 6 * p);
  write_rows(file, "/particles/tau", H5T_NATIVE_DOUBLE, b1.data(), n, off, tot, 1, chk);
  if (P.g) write_rows(file, "/particles/fluidity", H5T_NATIVE_DOUBLE, P.g, n, off, tot, 1, chk);
  if (P.gdot) write_rows(file, "/particles/gdot", H5T_NATIVE_DOUBLE, P.gdot, n, off, tot, 1, chk);
  S.particles.restore(P);
  H5Gclose(grp);

  // Grid: nodal mass and velocity (the state after the last grid update).
  hid_t ggrp = H5Gcreate2(file, "grid", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  const Grid<dim> &G = S.grid;
  const long nodes = (long)G.xm[0] * G.xm[1] * G.xm[2];
  std::vector<double> gm(nodes), gv(nodes * 3);
  const double *a;
  GM_CALL(VecGetArrayRead(G.global, &a));
  constexpr int ND = Grid<dim>::NDOF;
  for (long q = 0; q < nodes; ++q) {
    gm[q] = a[q * ND];
    for (int d = 0; d < 3; ++d) gv[q * 3 + d] = d < dim ? a[q * ND + 1 + d] : 0.0;
  }
  GM_CALL(VecRestoreArrayRead(G.global, &a));
  write_box(file, "/grid/mass", gm.data(), G.M, G.xs, G.xm, 1, chk);
  write_box(file, "/grid/velocity", gv.data(), G.M, G.xs, G.xm, 3, chk);
  H5Gclose(ggrp);
  if (S.bodies) {
    // Rigid bodies: kOutlinePoints points on each outline, with the body's rigid velocity
    // there and its index (rank 0 writes; every rank holds the same body state).
    std::vector<double> pos, vel, idx;
    double mid[3] = {0, 0, 0}, L = 0;
    for (int d = 0; d < dim; ++d) {
      mid[d] = 0.5 * (S.cfg.lo[d] + S.cfg.hi[d]);
      L += 0.25 * (S.cfg.hi[d] - S.cfg.lo[d]) * (S.cfg.hi[d] - S.cfg.lo[d]);
    }
    for (size_t k = 0; k < S.bodies->size(); ++k) {
      const BodyPose &q = S.bodies->pose(k);
      const double z = dim == 3 ? (S.bodies->spec(k).shape == BodyShape::Plane ? mid[2] : q.c[2]) : 0.0;
      for (const auto &x : body_outline(S.bodies->spec(k), q, mid, std::sqrt(L), z, kOutlinePoints)) {
        double v[3] = {0, 0, 0};
        body_velocity_at<dim>(S.bodies->velocity(k), S.bodies->omega(k), q, x.data(), v);
        pos.insert(pos.end(), x.begin(), x.end());
        vel.insert(vel.end(), v, v + 3);
        idx.push_back((double)k);
      }
    }
    const long nb = (long)idx.size(), mine = S.rank == 0 ? nb : 0;
    hid_t bgrp = H5Gcreate2(file, "bodies", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    write_rows(file, "/bodies/outline", H5T_NATIVE_DOUBLE, pos.data(), mine, 0, nb, 3, chk);
    write_rows(file, "/bodies/velocity", H5T_NATIVE_DOUBLE, vel.data(), mine, 0, nb, 3, chk);
    write_rows(file, "/bodies/body", H5T_NATIVE_DOUBLE, idx.data(), mine, 0, nb, 1, chk);
    H5Gclose(bgrp);
  }
  h5::attr_double(file, "time", S.time);
  h5::attr_double(file, "step", (double)S.nsteps);
  chk(H5Fclose(file), "close the file");
  int err = 0;
  if (S.rank == 0) err = std::rename(tmp.c_str(), path.c_str());
  MPI_Bcast(&err, 1, MPI_INT, 0, S.comm);
  if (err) throw UserError("cannot rename " + tmp + " to " + path + ": check -output_dir");
  frames_.push_back({S.time, name, tot});
  last_file = path;
  bool bad = false;
  std::string msg;
  if (S.rank == 0) {
    try {
      write_xdmf();
    } catch (const UserError &e) {
      bad = true;
      msg = e.what();
    }
  }
  collective_fail(S.comm, bad, msg);
}

template <int dim>
void Output<dim>::write_xdmf() const {
  const Simulation<dim> &S = sim_;
  const Grid<dim> &G = S.grid;
  const long nbody = S.bodies ? (long)S.bodies->size() * kOutlinePoints : 0;
  auto emit = [&](const std::string &fname, int which) { // 0 grid, 1 particles, 2 bodies
    const bool particles = which == 1;
    const std::string path = S.cfg.output_dir + "/" + fname, tmp = path + ".tmp";
    std::ofstream f(tmp);
    f << "<?xml version=\"1.0\" ?>\n<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n<Xdmf Version=\"2.0\">\n <Domain>\n";
    f << "  <Grid Name=\"" << (which == 1 ? "particles" : which == 2 ? "bodies" : "grid") << "\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
    for (const Frame &fr : frames_) {
      f << "   <Grid Name=\"t" << fr.t << "\" GridType=\"Uniform\">\n    <Time Value=\"" << fr.t << "\"/>\n";
      auto item = [&](const std::string &dims, const std::string &ds, const char *type = "Float", int prec = 8) {
        std::ostringstream s;
        s << "<DataItem Dimensions=\"" << dims << "\" NumberType=\"" << type << "\" Precision=\"" << prec << "\" Format=\"HDF\">" << fr.file << ":" << ds
          << "</DataItem>";
        return s.str();
      };
      if (which == 2) {
        const std::string N = std::to_string(nbody);
        f << "    <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << N << "\" NodesPerElement=\"1\"/>\n";
        f << "    <Geometry GeometryType=\"XYZ\">" << item(N + " 3", "/bodies/outline") << "</Geometry>\n";
        f << "    <Attribute Name=\"velocity\" AttributeType=\"Vector\" Center=\"Node\">" << item(N + " 3", "/bodies/velocity") << "</Attribute>\n";
        f << "    <Attribute Name=\"body\" AttributeType=\"Scalar\" Center=\"Node\">" << item(N, "/bodies/body") << "</Attribute>\n";
      } else if (particles) {
        const std::string N = std::to_string(fr.np);
        f << "    <Topology TopologyType=\"Polyvertex\" NumberOfElements=\"" << N << "\" NodesPerElement=\"1\"/>\n";
        f << "    <Geometry GeometryType=\"XYZ\">" << item(N + " 3", "/particles/position") << "</Geometry>\n";
        f << "    <Attribute Name=\"id\" AttributeType=\"Scalar\" Center=\"Node\">" << item(N, "/particles/id", "Int", 8) << "</Attribute>\n";
        f << "    <Attribute Name=\"velocity\" AttributeType=\"Vector\" Center=\"Node\">" << item(N + " 3", "/particles/velocity") << "</Attribute>\n";
        f << "    <Attribute Name=\"stress\" AttributeType=\"Tensor6\" Center=\"Node\">" << item(N + " 6", "/particles/stress") << "</Attribute>\n";
        for (const char *sc : {"mass", "volume", "density", "pressure", "tau"})
          f << "    <Attribute Name=\"" << sc << "\" AttributeType=\"Scalar\" Center=\"Node\">" << item(N, std::string("/particles/") + sc) << "</Attribute>\n";
        if (S.particles.fields().fluidity)
          f << "    <Attribute Name=\"fluidity\" AttributeType=\"Scalar\" Center=\"Node\">" << item(N, "/particles/fluidity") << "</Attribute>\n";
        if (S.particles.fields().gdot)
          f << "    <Attribute Name=\"gdot\" AttributeType=\"Scalar\" Center=\"Node\">" << item(N, "/particles/gdot") << "</Attribute>\n";
      } else {
        std::ostringstream dims;
        dims << G.M[2] << " " << G.M[1] << " " << G.M[0];
        f << "    <Topology TopologyType=\"3DCoRectMesh\" Dimensions=\"" << dims.str() << "\"/>\n";
        f << "    <Geometry GeometryType=\"ORIGIN_DXDYDZ\">\n     <DataItem Dimensions=\"3\" NumberType=\"Float\" Precision=\"8\" Format=\"XML\">"
          << (dim == 3 ? G.x0[2] : 0.0) << " " << G.x0[1] << " " << G.x0[0] << "</DataItem>\n"
          << "     <DataItem Dimensions=\"3\" NumberType=\"Float\" Precision=\"8\" Format=\"XML\">" << G.h << " " << G.h << " " << G.h << "</DataItem>\n    </Geometry>\n";
        f << "    <Attribute Name=\"mass\" AttributeType=\"Scalar\" Center=\"Node\">" << item(dims.str(), "/grid/mass") << "</Attribute>\n";
        f << "    <Attribute Name=\"velocity\" AttributeType=\"Vector\" Center=\"Node\">" << item(dims.str() + " 3", "/grid/velocity") << "</Attribute>\n";
      }
      f << "   </Grid>\n";
    }
    f << "  </Grid>\n </Domain>\n</Xdmf>\n";
    f.close();
    if (!f || std::rename(tmp.c_str(), path.c_str()) != 0) throw UserError("cannot write " + path + ": check -output_dir");
  };
  emit("particles.xmf", 1);
  emit("grid.xmf", 0);
  if (S.bodies) emit("bodies.xmf", 2);
}

template class Output<2>;
template class Output<3>;

} // namespace granmpm
