// The -dem_* options: every one registered in one PetscOptionsBegin/End block so that
// `granmpm -dem -help` lists it with its default; validated once here.
#include <cmath>
#include <cstring>

#include "granmpm/body_options.hpp"
#include "granmpm/config.hpp"
#include "granmpm/dem/dem.hpp"

namespace granmpm::dem {

namespace {

// PETSc's parse errors (a non-numeric value...) become one line naming the option.
#define DEM_OPT(name, ...)                                                                 \
  do {                                                                                     \
    if ((__VA_ARGS__) != 0) {                                                              \
      char v_[256] = "";                                                                   \
      PetscBool s_ = PETSC_FALSE;                                                          \
      PetscOptionsGetString(NULL, NULL, name, v_, sizeof v_, &s_);                         \
      throw UserError(std::string(name) + ": invalid value '" + v_ + "'");                 \
    }                                                                                      \
  } while (0)

// While the options are read PETSc returns errors instead of printing a trace.
struct QuietPetsc {
  QuietPetsc() {
    PetscErrorPrintf = PetscErrorPrintfNone;
    PetscPushErrorHandler(PetscReturnErrorHandler, NULL);
  }
  ~QuietPetsc() {
    PetscPopErrorHandler();
    PetscErrorPrintf = PetscErrorPrintfDefault;
  }
};

std::string fmt(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

void real_array(PetscOptionItems *PetscOptionsObject, const char *name, const char *help, std::array<double, 3> &a, int dim, bool &set) {
  PetscReal buf[3] = {a[0], a[1], a[2]};
  PetscInt n = 3;
  PetscBool flg = PETSC_FALSE;
  DEM_OPT(name, PetscOptionsRealArray(name, help, NULL, buf, &n, &flg));
  set = flg;
  if (!flg) return;
  if (n != dim) throw UserError(std::string(name) + " needs " + std::to_string(dim) + " comma-separated values for -dem_dim " + std::to_string(dim));
  for (int k = 0; k < 3; ++k) a[k] = k < n ? buf[k] : 0.0;
}

template <class E>
E choice(PetscOptionItems *PetscOptionsObject, const char *name, const char *help, const std::vector<std::string> &names, E def) {
  char buf[64];
  std::strncpy(buf, names[(int)def].c_str(), sizeof buf);
  PetscBool flg;
  std::string list;
  for (auto &n : names) list += (list.empty() ? "" : "|") + n;
  DEM_OPT(name, PetscOptionsString(name, (std::string(help) + " (" + list + ")").c_str(), NULL, buf, buf, sizeof buf, &flg));
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i] == buf) return (E)i;
  throw UserError(std::string(name) + " '" + buf + "' is not one of " + list);
}

void contact_opts(PetscOptionItems *PetscOptionsObject, const char *pre, ContactParams &p, const ContactParams *base) {
  auto nm = [&](const char *s) { return std::string(pre) + s; };
  PetscBool flg;
  if (!base) p.law = choice<Law>(PetscOptionsObject, nm("law").c_str(), "Contact law: linear spring-dashpot or Hertz-Mindlin (as LAMMPS gran/hertz/history)", {"linear", "hertz"}, p.law);
  DEM_OPT(nm("kn").c_str(), PetscOptionsReal(nm("kn").c_str(), "Normal stiffness k_n [N/m] (Hertz: per sqrt(overlap R_eff))", NULL, p.kn, &p.kn, &flg));
  DEM_OPT(nm("kt_ratio").c_str(), PetscOptionsReal(nm("kt_ratio").c_str(), "Tangential stiffness ratio k_t / k_n", NULL, p.kt_ratio, &p.kt_ratio, &flg));
  DEM_OPT(nm("e").c_str(), PetscOptionsReal(nm("e").c_str(), "Normal restitution coefficient e, 0 < e <= 1 (sets gamma_n)", NULL, p.e, &p.e, &flg));
  DEM_OPT(nm("gt_ratio").c_str(), PetscOptionsReal(nm("gt_ratio").c_str(), "Tangential damping ratio gamma_t / gamma_n", NULL, p.gt_ratio, &p.gt_ratio, &flg));
  DEM_OPT(nm("mu").c_str(), PetscOptionsReal(nm("mu").c_str(), "Coulomb friction coefficient mu >= 0", NULL, p.mu, &p.mu, &flg));
  DEM_OPT(nm("mu_roll").c_str(), PetscOptionsReal(nm("mu_roll").c_str(), "Rolling resistance coefficient (constant torque mu_r R_eff f_n), >= 0", NULL, p.mu_roll, &p.mu_roll, &flg));
  if (!base) {
    p.damping = choice<Damping>(PetscOptionsObject, nm("damping").c_str(),
                                "gamma_n from e: exact (calibrated: no attraction, measured e = requested) or seed (the seed's formula)", {"seed", "exact"}, p.damping);
    PetscBool mm = p.mean_mass ? PETSC_TRUE : PETSC_FALSE;
    DEM_OPT(nm("mean_mass").c_str(), PetscOptionsBool(nm("mean_mass").c_str(), "Damping from the mean grain mass (the seed's form) instead of each contact's effective mass", NULL, mm, &mm, &flg));
    p.mean_mass = mm;
  }
}

void check_contact(const std::string &pre, const ContactParams &p) {
  if (!(p.kn > 0)) throw UserError(pre + "kn must be > 0 (got " + fmt(p.kn) + ")");
  if (!(p.kt_ratio >= 0)) throw UserError(pre + "kt_ratio must be >= 0 (got " + fmt(p.kt_ratio) + ")");
  if (!(p.e > 0 && p.e <= 1)) throw UserError(pre + "e must be in (0, 1] (got " + fmt(p.e) + ")");
  if (!(p.gt_ratio >= 0)) throw UserError(pre + "gt_ratio must be >= 0 (got " + fmt(p.gt_ratio) + ")");
  if (!(p.mu >= 0)) throw UserError(pre + "mu must be >= 0 (got " + fmt(p.mu) + ")");
  if (!(p.mu_roll >= 0)) throw UserError(pre + "mu_roll must be >= 0 (got " + fmt(p.mu_roll) + ")");
}

// The box, its faces, the silo plate and gravity.
void box_opts(PetscOptionItems *PetscOptionsObject, Config &c) {
  PetscBool flg;
  bool set;
  PetscInt dim = c.dim;
  DEM_OPT("-dem_dim", PetscOptionsInt("-dem_dim", "Dimension: 2 (disks) or 3 (spheres)", NULL, dim, &dim, &flg));
  if (dim != 2 && dim != 3) throw UserError("-dem_dim must be 2 or 3 (got " + std::to_string(dim) + ")");
  c.dim = (int)dim;
  real_array(PetscOptionsObject, "-dem_lo", "Lower corner of the box x,y[,z] [m]", c.lo, c.dim, set);
  real_array(PetscOptionsObject, "-dem_hi", "Upper corner of the box x,y[,z] [m]", c.hi, c.dim, set);
  char per[8] = "";
  DEM_OPT("-dem_periodic", PetscOptionsString("-dem_periodic", "Periodic directions, e.g. x or xz (others: frictional wall planes)", NULL, per, per, sizeof per, &flg));
  for (const char *p = per; *p; ++p) {
    if (*p < 'x' || *p >= 'x' + c.dim) throw UserError(std::string("-dem_periodic '") + per + "': use letters among " + (c.dim == 3 ? "xyz" : "xy"));
    c.periodic[*p - 'x'] = true;
  }
  char outl[32] = "";
  DEM_OPT("-dem_outlet", PetscOptionsString("-dem_outlet", "Open faces, comma-separated among xlo,xhi,ylo,yhi,zlo,zhi: grains leave through them and are removed", NULL, outl, outl, sizeof outl, &flg));
  for (std::string rest = outl; !rest.empty();) {
    const size_t cpos = rest.find(',');
    const std::string f = rest.substr(0, cpos);
    rest = cpos == std::string::npos ? "" : rest.substr(cpos + 1);
    if (f.size() != 3 || f[0] < 'x' || f[0] >= 'x' + c.dim || (f.substr(1) != "lo" && f.substr(1) != "hi"))
      throw UserError("-dem_outlet: '" + f + "' is not a face (xlo, xhi, ylo, yhi" + (c.dim == 3 ? ", zlo, zhi)" : ")"));
    c.outlet[f[0] - 'x'][f.substr(1) == "hi"] = true;
  }
  DEM_OPT("-dem_plate_y", PetscOptionsReal("-dem_plate_y", "Silo: height of a horizontal plate with an orifice (a frictional wall like -dem_wall_*)", NULL, c.plate_y, &c.plate_y, &flg));
  c.plate = flg;
  DEM_OPT("-dem_orifice", PetscOptionsReal("-dem_orifice", "Silo: orifice width D (2D slot; 3D round hole) [m]", NULL, c.orifice, &c.orifice, &flg));
  DEM_OPT("-dem_orifice_x", PetscOptionsReal("-dem_orifice_x", "Silo: x of the orifice centre [m]", NULL, c.orifice_x, &c.orifice_x, &flg));
  DEM_OPT("-dem_orifice_z", PetscOptionsReal("-dem_orifice_z", "Silo (3D): z of the orifice centre [m]", NULL, c.orifice_z, &c.orifice_z, &flg));
  real_array(PetscOptionsObject, "-dem_gravity", "Gravity gx,gy[,gz] [m/s^2]", c.gravity, c.dim, set);
}

// The grains, their contacts, the time step and the initial scene.
void grain_opts(PetscOptionItems *PetscOptionsObject, Config &c) {
  PetscBool flg;
  bool set;
  DEM_OPT("-dem_density", PetscOptionsReal("-dem_density", "Grain density [kg/m^3] (2D: mass per unit thickness / area)", NULL, c.density, &c.density, &flg));
  DEM_OPT("-dem_radius", PetscOptionsReal("-dem_radius", "Mean grain radius [m]", NULL, c.radius, &c.radius, &flg));
  c.dist = choice<RadiusDist>(PetscOptionsObject, "-dem_radius_dist", "Radius distribution", {"mono", "uniform", "normal"}, c.dist);
  DEM_OPT("-dem_radius_spread", PetscOptionsReal("-dem_radius_spread", "Uniform: half-width / radius; normal: sigma / radius (truncated at 2 sigma)", NULL, c.spread, &c.spread, &flg));
  contact_opts(PetscOptionsObject, "-dem_", c.contact, nullptr);
  c.wall = c.contact;
  contact_opts(PetscOptionsObject, "-dem_wall_", c.wall, &c.contact);
  // Per face (and the plate): friction and restitution over the -dem_wall_ values.
  for (int f = 0; f <= 2 * c.dim; ++f) {
    const std::string mu = "-dem_wall_mu_" + c.face_name(f), e = "-dem_wall_e_" + c.face_name(f);
    const std::string where = f < 2 * c.dim ? "the " + c.face_name(f) + " face" : "the silo plate";
    PetscReal v = c.wall.mu;
    DEM_OPT(mu.c_str(), PetscOptionsReal(mu.c_str(), ("Coulomb friction of " + where + " (default -dem_wall_mu)").c_str(), NULL, v, &v, &flg));
    if (flg) c.face_mu[f] = v;
    v = c.wall.e;
    DEM_OPT(e.c_str(), PetscOptionsReal(e.c_str(), ("Restitution of " + where + ", 0 < e <= 1 (default -dem_wall_e)").c_str(), NULL, v, &v, &flg));
    if (flg) c.face_e[f] = v;
  }
  DEM_OPT("-dem_skin", PetscOptionsReal("-dem_skin", "Verlet skin [m] (0: 0.3 of the largest radius)", NULL, c.skin, &c.skin, &flg));
  DEM_OPT("-dem_cell", PetscOptionsReal("-dem_cell", "Broad-phase cell size [m] (0: largest diameter + skin)", NULL, c.cell, &c.cell, &flg));
  DEM_OPT("-dem_dt", PetscOptionsReal("-dem_dt", "Fixed time step [s] (0: t_c / -dem_steps_per_contact)", NULL, c.dt, &c.dt, &flg));
  DEM_OPT("-dem_steps_per_contact", PetscOptionsReal("-dem_steps_per_contact", "Automatic dt = t_c / N of the lightest contact: N (>= 5)", NULL, c.steps_per_contact, &c.steps_per_contact, &flg));
  c.integrator = choice<Integrator>(PetscOptionsObject, "-dem_integrator", "Time integrator", {"verlet", "euler"}, c.integrator);
  DEM_OPT("-dem_overlap_tol", PetscOptionsReal("-dem_overlap_tol", "Largest initial overlap / radius accepted", NULL, c.overlap_tol, &c.overlap_tol, &flg));
  c.scene = choice<Scene>(PetscOptionsObject, "-dem_scene", "Initial grains: a jittered lattice block, or an explicit list (-dem_grains)", {"block", "list"}, c.scene);
  c.block_lo = c.lo;
  c.block_hi = c.hi;
  real_array(PetscOptionsObject, "-dem_block_lo", "Block scene: lower corner of the lattice [m] (default: the box)", c.block_lo, c.dim, set);
  real_array(PetscOptionsObject, "-dem_block_hi", "Block scene: upper corner of the lattice [m] (default: the box)", c.block_hi, c.dim, set);
  DEM_OPT("-dem_spacing", PetscOptionsReal("-dem_spacing", "Block scene: lattice spacing [m] (0: 2.02 largest radius)", NULL, c.spacing, &c.spacing, &flg));
  c.lattice = choice<Lattice>(PetscOptionsObject, "-dem_lattice", "Block scene: lattice (cubic, or dense: fcc in 3D, hexagonal in 2D)", {"cubic", "dense"}, c.lattice);
  DEM_OPT("-dem_jitter", PetscOptionsReal("-dem_jitter", "Block scene: random site offset as a fraction of the free gap, 0..1", NULL, c.jitter, &c.jitter, &flg));
  real_array(PetscOptionsObject, "-dem_velocity", "Initial velocity vx,vy[,vz] [m/s]", c.v0, c.dim, set);
  {
    // 2D disks spin about z only: one value; spheres: wx,wy,wz.
    PetscReal buf[3] = {0, 0, 0};
    PetscInt n = 3;
    DEM_OPT("-dem_spin", PetscOptionsRealArray("-dem_spin", "Initial angular velocity of every grain: wx,wy,wz (3D) or wz (2D) [rad/s]", NULL, buf, &n, &flg));
    if (flg && n != (c.dim == 3 ? 3 : 1)) throw UserError(std::string("-dem_spin needs ") + (c.dim == 3 ? "3 comma-separated values wx,wy,wz" : "1 value wz") + " for -dem_dim " + std::to_string(c.dim));
    if (flg) c.w0 = c.dim == 3 ? std::array<double, 3>{buf[0], buf[1], buf[2]} : std::array<double, 3>{0, 0, buf[0]};
  }
  DEM_OPT("-dem_velocity_random", PetscOptionsReal("-dem_velocity_random", "Random velocity amplitude per component [m/s]", NULL, c.vrand, &c.vrand, &flg));
  PetscInt seed = (PetscInt)c.seed;
  DEM_OPT("-dem_seed", PetscOptionsInt("-dem_seed", "Random seed (radii, jitter, velocities; by grain id)", NULL, seed, &seed, &flg));
  c.seed = (uint64_t)seed;
  {
    std::vector<PetscReal> buf(7 * 1000);
    PetscInt n = (PetscInt)buf.size();
    DEM_OPT("-dem_grains", PetscOptionsRealArray("-dem_grains", "List scene: x,y[,z],r,vx,vy[,vz] per grain (up to 1000)", NULL, buf.data(), &n, &flg));
    if (flg) {
      const int per = 2 * c.dim + 1;
      if (n % per) throw UserError("-dem_grains needs " + std::to_string(per) + " values per grain (x,y" + (c.dim == 3 ? ",z" : "") + ",r,vx,vy" + (c.dim == 3 ? ",vz" : "") + ")");
      c.grains.assign(buf.begin(), buf.begin() + n);
    }
  }
}

// The run: its length, output and checkpoints.
void run_opts(PetscOptionItems *PetscOptionsObject, Config &c) {
  PetscBool flg;
  DEM_OPT("-dem_t_end", PetscOptionsReal("-dem_t_end", "End time [s]", NULL, c.t_end, &c.t_end, &flg));
  PetscInt ms = c.max_steps, oe = c.output_every, fe = c.fields_every, ce = c.checkpoint_every;
  DEM_OPT("-dem_max_steps", PetscOptionsInt("-dem_max_steps", "Stop after this many steps (-1: run to -dem_t_end)", NULL, ms, &ms, &flg));
  DEM_OPT("-dem_output_every", PetscOptionsInt("-dem_output_every", "Summary CSV row every n steps (0: 100 rows over the run)", NULL, oe, &oe, &flg));
  DEM_OPT("-dem_fields_every", PetscOptionsInt("-dem_fields_every", "HDF5+XDMF grain snapshot every n steps (0: first and last)", NULL, fe, &fe, &flg));
  DEM_OPT("-dem_checkpoint_every", PetscOptionsInt("-dem_checkpoint_every", "Checkpoint every n steps (0: at the end only, if -dem_checkpoint)", NULL, ce, &ce, &flg));
  c.max_steps = ms;
  c.output_every = oe;
  c.fields_every = fe;
  c.checkpoint_every = ce;
  char buf[PETSC_MAX_PATH_LEN];
  std::strncpy(buf, c.output_dir.c_str(), sizeof buf);
  DEM_OPT("-dem_output_dir", PetscOptionsString("-dem_output_dir", "Output directory (summary CSV dem_summary.csv, grains_*.h5/.xmf)", NULL, buf, buf, sizeof buf, &flg));
  c.output_dir = buf;
  PetscBool b = c.output_overwrite ? PETSC_TRUE : PETSC_FALSE;
  DEM_OPT("-dem_output_overwrite", PetscOptionsBool("-dem_output_overwrite", "Replace an earlier run's results in -dem_output_dir (without it a new run into such a directory is refused)", NULL, b, &b, &flg));
  c.output_overwrite = b;
  b = c.fields ? PETSC_TRUE : PETSC_FALSE;
  DEM_OPT("-dem_fields", PetscOptionsBool("-dem_fields", "Write HDF5+XDMF grain snapshots", NULL, b, &b, &flg));
  c.fields = b;
  b = c.force_chains ? PETSC_TRUE : PETSC_FALSE;
  DEM_OPT("-dem_force_chains", PetscOptionsBool("-dem_force_chains", "Snapshots also hold the contact network: a line per force-carrying grain pair with its normal and tangential force (chains.xmf)", NULL, b, &b, &flg));
  c.force_chains = b;
  b = c.orientation ? PETSC_TRUE : PETSC_FALSE;
  DEM_OPT("-dem_orientation", PetscOptionsBool("-dem_orientation", "Keep and integrate each grain's orientation (3D quaternion, 2D angle) for snapshots and checkpoints; false: none kept (32 B per sphere less and a faster step; no other result changes)", NULL, b, &b, &flg));
  c.orientation = b;
  b = c.quiet ? PETSC_TRUE : PETSC_FALSE;
  DEM_OPT("-dem_quiet", PetscOptionsBool("-dem_quiet", "No progress lines", NULL, b, &b, &flg));
  c.quiet = b;
  buf[0] = 0;
  DEM_OPT("-dem_checkpoint", PetscOptionsString("-dem_checkpoint", "Write a checkpoint (grains, springs) to this HDF5 file at the end", NULL, buf, buf, sizeof buf, &flg));
  c.checkpoint = buf;
  buf[0] = 0;
  DEM_OPT("-dem_restart", PetscOptionsString("-dem_restart", "Restart from this checkpoint (same options and rank count give the same bits)", NULL, buf, buf, sizeof buf, &flg));
  c.restart = buf;
}

// Throws UserError on bad values (the run stops, so the unfinished options block is moot).
// bodies (granmpm -dem): the rigid bodies' options too, read by their own component
// (body_options.hpp) into a host-style Config of the same dimension.
PetscErrorCode read_options(MPI_Comm comm, Config &c, granmpm::Config *bodies, BodyOptions &bo) {
  PetscOptionsBegin(comm, NULL, "GranMPM DEM options (granmpm -dem ...; docs/dem.md)", NULL);
  box_opts(PetscOptionsObject, c);
  grain_opts(PetscOptionsObject, c);
  run_opts(PetscOptionsObject, c);
  if (bodies) {
    bodies->dim = c.dim;
    const char *failed = nullptr;
    std::string notes;
    if (bo.read(PetscOptionsObject, *bodies, failed, notes)) DEM_OPT(failed ? failed : "-body0_shape", 1);
    if (!notes.empty()) throw UserError(notes);
  }
  PetscOptionsEnd();
  return 0;
}

// The grid-contact options of the MPM's bodies mean nothing to grains (they take the
// -dem_wall_* law): refused rather than ignored.
void refuse_grid_contact_options(const granmpm::Config &h) {
  std::vector<std::string> names = {"-body_contact_layer"};
  for (const BodySpec &b : h.bodies)
    for (const char *o : {"contact", "friction"}) names.push_back("-body" + std::to_string(b.index) + "_" + o);
  for (const std::string &n : names) {
    PetscBool set = PETSC_FALSE;
    GM_CALL(PetscOptionsHasName(NULL, NULL, n.c_str(), &set));
    if (set) throw UserError(n + " sets the MPM grid's contact with a body; grains touch bodies with the wall law (-dem_wall_kn, -dem_wall_mu, ...): drop " + n);
  }
}

} // namespace

std::string Config::face_name(int f) const {
  if (f == 2 * dim) return "plate";
  return std::string(1, "xyz"[f / 2]) + (f % 2 ? "hi" : "lo");
}

Config Config::from_options(MPI_Comm comm, bool check, bool bodies) {
  Config c;
  granmpm::Config h;
  BodyOptions bo;
  {
    QuietPetsc q;
    GM_CALL(read_options(comm, c, bodies ? &h : nullptr, bo));
  }
  if (bodies) {
    bo.finish(h);
    BodyOptions::validate(h);
    refuse_grid_contact_options(h);
    c.bodies = h.bodies;
    c.bodies_interval = h.bodies_interval;
  }
  if (check) c.validate();
  return c;
}

void Config::validate() const {
  for (int k = 0; k < dim; ++k)
    if (!(hi[k] > lo[k])) throw UserError("-dem_hi must exceed -dem_lo in every direction");
  if (!(radius > 0)) throw UserError("-dem_radius must be > 0 (got " + fmt(radius) + ")");
  if (!(density > 0)) throw UserError("-dem_density must be > 0 (got " + fmt(density) + ")");
  const double smax = dist == RadiusDist::Normal ? 0.5 : 1.0;
  if (!(spread >= 0 && spread < smax)) throw UserError("-dem_radius_spread must be in [0, " + fmt(smax) + ") for this -dem_radius_dist (got " + fmt(spread) + ")");
  check_contact("-dem_", contact);
  check_contact("-dem_wall_", wall);
  for (int f = 0; f <= 2 * dim; ++f) {
    const bool mu = !std::isnan(face_mu[f]), e = !std::isnan(face_e[f]);
    if (!mu && !e) continue;
    const std::string opt = std::string(mu ? "-dem_wall_mu_" : "-dem_wall_e_") + face_name(f);
    if (mu && !(face_mu[f] >= 0)) throw UserError(opt + " must be >= 0 (got " + fmt(face_mu[f]) + ")");
    if (e && !(face_e[f] > 0 && face_e[f] <= 1)) throw UserError("-dem_wall_e_" + face_name(f) + " must be in (0, 1] (got " + fmt(face_e[f]) + ")");
    if (f == 2 * dim && !plate) throw UserError(opt + " sets the silo plate's contact, but there is no plate: add -dem_plate_y or drop " + opt);
    if (f < 2 * dim && periodic[f / 2]) throw UserError(opt + ": the " + "xyz"[f / 2] + " faces are periodic (no wall there): drop " + opt);
    if (f < 2 * dim && outlet[f / 2][f % 2]) throw UserError(opt + ": the " + face_name(f) + " face is an outlet (no wall there): drop " + opt);
  }
  if (!(skin >= 0)) throw UserError("-dem_skin must be >= 0");
  if (!(cell >= 0)) throw UserError("-dem_cell must be >= 0");
  if (!(dt >= 0)) throw UserError("-dem_dt must be >= 0");
  if (!(steps_per_contact >= 5)) throw UserError("-dem_steps_per_contact must be >= 5 (got " + fmt(steps_per_contact) + ")");
  if (!(overlap_tol >= 0)) throw UserError("-dem_overlap_tol must be >= 0");
  if (!(jitter >= 0 && jitter <= 1)) throw UserError("-dem_jitter must be in [0, 1]");
  if (!(t_end >= 0)) throw UserError("-dem_t_end must be >= 0");
  for (int k = 0; k < dim; ++k)
    if (periodic[k] && (outlet[k][0] || outlet[k][1])) throw UserError(std::string("-dem_outlet: the ") + "xyz"[k] + " faces are periodic (-dem_periodic)");
  if (plate && !(plate_y > lo[1] && plate_y < hi[1])) throw UserError("-dem_plate_y must lie inside the box in y");
  if (plate && !(orifice >= 0)) throw UserError("-dem_orifice must be >= 0");
  if (scene == Scene::List && grains.empty()) throw UserError("-dem_scene list needs -dem_grains");
  for (size_t g = 0; scene == Scene::List && g * (2 * dim + 1) < grains.size(); ++g)
    if (!(grains[g * (2 * dim + 1) + dim] > 0)) throw UserError("-dem_grains: grain " + std::to_string(g) + " has a radius <= 0");
}

} // namespace granmpm::dem
