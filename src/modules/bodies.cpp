// BodyModule: rigid bodies coupled to the grid (modules.hpp). The contact itself is
// RigidBodies::apply (rigid_body.hpp); this file wires it into the step.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <sstream>

#include "granmpm/checkpoint.hpp"
#include "granmpm/modules.hpp"
#include "granmpm/output.hpp"

namespace granmpm {

template <int dim>
BodyModule<dim>::~BodyModule() {
  if (csv_) std::fclose(csv_);
}

template <int dim>
void BodyModule<dim>::begin_step(State<dim> &S, double) {
  B_ = S.bodies.get();
  B_->set_time(S.time); // body poses at the start of the step
}

template <int dim>
void BodyModule<dim>::begin_grid(State<dim> &S, double, bool with_force) {
  B_ = S.bodies.get();
  if (with_force) B_->begin_forces();
}

template <int dim>
void BodyModule<dim>::node(const NodeAt &n, double *v, double dt, bool with_force) {
  B_->apply(n.x, n.m, v, with_force ? dt : 0.0); // owned nodes: forces counted once
}

template <int dim>
void BodyModule<dim>::end_grid(State<dim> &S, double dt, bool with_force) {
  if (!with_force) return;
  RigidBodies<dim> &bodies = *S.bodies;
  std::vector<double> &f = bodies.forces(), &mc = bodies.contact_mass();
  MPI_Allreduce(MPI_IN_PLACE, f.data(), (int)f.size(), MPI_DOUBLE, MPI_SUM, S.comm);
  MPI_Allreduce(MPI_IN_PLACE, mc.data(), (int)mc.size(), MPI_DOUBLE, MPI_SUM, S.comm);
  // Bodies supply energy: their work on the material, -(F . V + T omega) dt with the
  // velocity the contact used, raises the bound of the energy guard.
  for (size_t b = 0; b < bodies.size(); ++b) {
    double pw = -f[4 * b + 3] * bodies.omega(b);
    for (int d = 0; d < dim; ++d) pw -= f[4 * b + d] * bodies.velocity(b)[d];
    S.energy_bound += dt * std::max(0.0, pw);
  }
  // A dynamic body is updated explicitly with the impulse of its contact nodes, which
  // were set to its velocity of the step start: the next step's velocity change is about
  // -(m_contact / M) times this one's (added mass), unstable once m_contact > M (for a
  // free rotation: sum m r^2 > I). Same numbers on every rank after the reduction.
  for (size_t b = 0; b < bodies.size(); ++b) {
    if (!bodies.dynamic(b)) continue;
    const BodySpec &B = bodies.spec(b);
    const bool free_translation = !B.lock[0] || !B.lock[1] || (dim == 3 && !B.lock[2]);
    std::ostringstream m;
    if (free_translation && mc[2 * b] > B.mass)
      m << "at t = " << S.time << " the grid mass at the contact nodes of dynamic rigid body " << b << " (" << S.body_names[b] << "), " << mc[2 * b]
        << " kg, exceeds its mass -body" << B.index << "_mass " << B.mass << ": the explicit body update is unstable (added mass); raise -body" << B.index
        << "_mass, lock the axes that need not move (-body" << B.index << "_lock), or use a finer grid";
    else if (!B.lock[3] && mc[2 * b + 1] > B.inertia)
      m << "at t = " << S.time << " the moment of inertia of the grid mass at the contact nodes of dynamic rigid body " << b << " (" << S.body_names[b] << "), "
        << mc[2 * b + 1] << " kg m^2, exceeds its -body" << B.index << "_inertia " << B.inertia
        << ": the explicit body update is unstable (added mass); raise -body" << B.index << "_inertia or lock its rotation (-body" << B.index << "_lock rot)";
    if (!m.str().empty()) throw UserError(m.str()); // identical on every rank (reduced sums)
  }
}

template <int dim>
void BodyModule<dim>::end_step(State<dim> &S, double dt) {
  // Dynamic bodies take this step's reduced contact force (the grid updates used their
  // start-of-step velocity); kinematic ones move to t + dt. Particles are then checked
  // against the end-of-step poses.
  const double gf = S.gravity_factor(S.time);
  double acc[3] = {0, 0, 0};
  for (int d = 0; d < dim; ++d) acc[d] = S.cfg.gravity[d] * gf;
  S.bodies->advance(S.time, dt, acc);
  particles_inside(S);
}

template <int dim>
void BodyModule<dim>::particles_inside(State<dim> &S) {
  // Same treatment as walls (Particles::migrate): a particle the interpolated velocity
  // carried less than a cell into a body is put back onto its surface along the normal;
  // counted and reported. Deeper penetration means the body or the flow moves too far
  // per step: the run stops.
  const RigidBodies<dim> &bodies = *S.bodies;
  const double h = S.grid.h;
  ParticleView<dim> P = S.particles.get();
  long hits = 0;
  bool bad = false;
  std::string msg;
  for (PetscInt p = 0; p < P.n; ++p) {
    double *x = P.x + p * dim;
    for (size_t k = 0; k < bodies.size(); ++k) {
      const SdfResult s = bodies.sdf_full(k, x);
      if (!(s.d < 0)) continue;
      if (-s.d <= h) {
        // Position only: the velocity came from the grid, where the contact already acted
        // (changing it here would be momentum the body forces do not account for).
        for (int d = 0; d < dim; ++d) x[d] -= s.d * s.n[d];
        ++hits;
      } else if (!bad) {
        bad = true;
        std::ostringstream m;
        m << "particle " << P.id[p] << " is " << -s.d / h << " cells inside rigid body " << k << " (" << S.body_names[k] << ") at t = " << S.time << " (position";
        for (int d = 0; d < dim; ++d) m << " " << x[d];
        m << "): a body or the flow moves more than a cell per step; reduce -dt or -cfl, or the body's velocity/omega";
        msg = m.str();
      }
    }
  }
  S.particles.restore(P);
  collective_fail(S.comm, bad, msg);
  long all = 0;
  MPI_Allreduce(&hits, &all, 1, MPI_LONG, MPI_SUM, S.comm);
  S.body_corrections += all;
}

template <int dim>
void BodyModule<dim>::write_checkpoint(const State<dim> &S, CheckpointIO &io) const {
  // Pose, velocity (dynamic bodies are integrated, not recomputed from the time) and the
  // last force sums, identical on every rank.
  io.write_attr("bodies_state", S.bodies->state());
}

template <int dim>
void BodyModule<dim>::read_checkpoint(State<dim> &S, CheckpointIO &io) {
  if (!io.has_attr("bodies_state") || !S.bodies->set_state(io.read_attr("bodies_state"))) io.bad("the rigid-body state is missing or has another size");
}

template <int dim>
void BodyModule<dim>::backup(const State<dim> &S) {
  backup_ = S.bodies->state();
}

template <int dim>
void BodyModule<dim>::restore(State<dim> &S) {
  S.bodies->set_state(backup_);
}

template <int dim>
void BodyModule<dim>::record(const State<dim> &S, bool start) {
  const Config &c = S.cfg;
  const bool due = start ? S.nsteps == 0
                         : (S.nsteps % c.bodies_interval == 0 || (c.output_interval > 0 && S.nsteps % c.output_interval == 0) || S.time >= c.t_end - 1e-12 * c.t_end);
  if (due) write_row(S);
}

template <int dim>
void BodyModule<dim>::write_row(const State<dim> &S) {
  // Rank 0 writes; a failure (disk full, permission) stops every rank with the cause.
  const Config &cfg = S.cfg;
  bool bad = false;
  std::string msg;
  const std::string path = cfg.output_dir + "/bodies.csv";
  if (S.rank == 0 && !csv_) {
    std::filesystem::create_directories(cfg.output_dir);
    if (S.nsteps > 0 && !cfg.restart.empty()) {
      // A restart appends; rows after the checkpoint's time (written before the old run
      // stopped) would be doubled: keep the header and the rows up to now.
      std::FILE *in = std::fopen(path.c_str(), "r");
      std::string kept;
      if (in) {
        char line[4096];
        for (bool first = true; std::fgets(line, sizeof line, in); first = false)
          if (first || std::strtod(line, nullptr) <= S.time * (1 + 1e-12)) kept += line;
        std::fclose(in);
        try {
          std::FILE *out = open_atomic(path);
          std::fputs(kept.c_str(), out);
          close_atomic(out);
        } catch (const UserError &e) {
          bad = true;
          msg = e.what();
        }
      }
    }
    if (!bad) csv_ = std::fopen(path.c_str(), S.nsteps > 0 && !cfg.restart.empty() ? "a" : "w");
    if (!bad && !csv_) {
      bad = true;
      msg = "cannot write " + path + " (" + std::strerror(errno) + "): check -output_dir";
    }
    if (csv_ && std::ftell(csv_) == 0)
      std::fprintf(csv_, dim == 3 ? "time,body,x,y,z,vx,vy,vz,omega,fx,fy,fz,torque,angle\n" : "time,body,x,y,vx,vy,omega,fx,fy,torque,angle\n");
  }
  if (S.rank == 0 && csv_) {
    // Pose and velocity at the current time; forces of the last step's grid update (0 before the first).
    const RigidBodies<dim> &now = *S.bodies;
    for (size_t k = 0; k < now.size(); ++k) {
      const BodyPose &q = now.pose(k);
      const double *f = &now.forces()[4 * k];
      std::fprintf(csv_, "%.9e,%zu", S.time, k);
      for (int d = 0; d < dim; ++d) std::fprintf(csv_, ",%.9e", q.c[d]);
      for (int d = 0; d < dim; ++d) std::fprintf(csv_, ",%.9e", now.velocity(k)[d]);
      std::fprintf(csv_, ",%.9e", now.omega(k));
      for (int d = 0; d < dim; ++d) std::fprintf(csv_, ",%.9e", f[d]);
      std::fprintf(csv_, ",%.9e,%.9e\n", f[3], q.angle);
    }
    errno = 0;
    if (std::fflush(csv_) != 0 || std::ferror(csv_)) {
      bad = true;
      msg = "cannot write " + path + " (" + (errno ? std::strerror(errno) : "write failed") + "): check -output_dir";
    }
  }
  collective_fail(S.comm, bad, msg);
}

template class BodyModule<2>;
template class BodyModule<3>;

} // namespace granmpm
