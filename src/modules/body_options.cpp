// The rigid bodies' options (body_options.hpp): -body<k>_* read, converted, checked and
// signed by the body component.
#include "granmpm/body_options.hpp"

#include <cmath>
#include <cstring>
#include <sstream>

#include "granmpm/option_names.hpp"
#include "../options_util.hpp"

namespace granmpm {

using opt::bad;
using opt::fmt;
using opt::keep;
using opt::read_vec;

// Raw values read inside the options block, converted afterwards.
struct BodyOptions::Raw {
  char bshape[Config::kMaxBodies][64] = {}, bcontact[Config::kMaxBodies][64] = {};
  PetscReal bcenter[Config::kMaxBodies][3] = {}, bhalf[Config::kMaxBodies][3] = {}, bvel[Config::kMaxBodies][3] = {};
  PetscInt nbcenter[Config::kMaxBodies] = {}, nbhalf[Config::kMaxBodies] = {}, nbvel[Config::kMaxBodies] = {};
  PetscBool bset[Config::kMaxBodies] = {};
  BodySpec bspec[Config::kMaxBodies];
  char bmotion[Config::kMaxBodies][64] = {}, block[Config::kMaxBodies][64] = {}, bpath[Config::kMaxBodies][4096] = {};
  PetscReal bforce[Config::kMaxBodies][3] = {};
  PetscInt nbforce[Config::kMaxBodies] = {};
  PetscBool binertia_set[Config::kMaxBodies] = {};
  std::string bdyn_opt[Config::kMaxBodies]; // a dynamic-only option given (for a kinematic body: an error)
  double contact_layer = 0.5;
  PetscInt interval = 100;
};

BodyOptions::BodyOptions() : r_(std::make_unique<Raw>()) {}
BodyOptions::~BodyOptions() = default;

namespace {
// -body<k>_lock: comma-separated x,y,z,rot (z in 3D only) or none.
void parse_lock(const char *opt, const std::string &text, int dim, std::array<bool, 4> &lock) {
  lock = {{false, false, false, false}};
  if (text.empty() || text == "none") return;
  std::istringstream in(text);
  for (std::string tok; std::getline(in, tok, ',');) {
    const std::vector<const char *> names = {"x", "y", "z", "rot"};
    int i = -1;
    for (int j = 0; j < 4; ++j)
      if (tok == names[j]) i = j;
    if (i < 0 || (i == 2 && dim == 2)) bad(std::string(opt) + ": unknown degree of freedom '" + tok + "' (a comma-separated list of " + (dim == 2 ? "x,y,rot" : "x,y,z,rot") + ", or none)");
    lock[i] = true;
  }
}

// -body<k>_path: waypoints 't,x,y[,z]' separated by ';', at least two, t strictly increasing.
std::vector<std::array<double, 4>> parse_path(const char *opt, const std::string &text, int dim) {
  std::vector<std::array<double, 4>> path;
  std::istringstream in(text);
  for (std::string wp; std::getline(in, wp, ';');) {
    std::array<double, 4> w{{0, 0, 0, 0}};
    std::istringstream ws(wp);
    int n = 0;
    for (std::string num; std::getline(ws, num, ',');) {
      char *end = nullptr;
      const double v = std::strtod(num.c_str(), &end);
      if (num.empty() || end == num.c_str() || *end != 0 || !std::isfinite(v) || n > dim)
        bad(std::string(opt) + ": waypoint " + std::to_string(path.size()) + " '" + wp + "' is not t,x,y" + (dim == 3 ? ",z" : "") + " (waypoints 't,x,y" + (dim == 3 ? ",z" : "") + "' separated by ';')");
      w[n++] = v;
    }
    if (n != dim + 1)
      bad(std::string(opt) + ": waypoint " + std::to_string(path.size()) + " '" + wp + "' has " + std::to_string(n) + " numbers, expected " + std::to_string(dim + 1) + " (t,x,y" + (dim == 3 ? ",z" : "") + ")");
    if (!path.empty() && !(w[0] > path.back()[0]))
      bad(std::string(opt) + ": waypoint times must increase (waypoint " + std::to_string(path.size()) + " at t = " + fmt(w[0]) + " after t = " + fmt(path.back()[0]) + ")");
    path.push_back(w);
  }
  if (path.size() < 2) bad(std::string(opt) + ": needs at least two waypoints 't,x,y" + (dim == 3 ? ",z" : "") + "' separated by ';'");
  return path;
}
} // namespace

// The options of body k are read (and listed by -help) for body 0 and for bodies that are
// given; options of a body without -bodyK_shape are reported as unused. (One registration
// per option, in the order -help lists them: longer than 80 lines for that reason.)
PetscErrorCode BodyOptions::read(PetscOptionItems *PetscOptionsObject, const Config &c, const char *&failed, std::string &notes_) {
  Raw &r = *r_;
  PetscBool flag;
  PetscFunctionBeginUser;
  r.contact_layer = c.body_contact_layer;
  r.interval = (PetscInt)c.bodies_interval;
  GM_OPT("-body_contact_layer", PetscOptionsReal("-body_contact_layer", "Rigid bodies: grid nodes with signed distance < layer * h are contact nodes (cells, in [0, 2])", NULL, r.contact_layer, &r.contact_layer, &flag));
  GM_OPT("-bodies_interval", PetscOptionsInt("-bodies_interval", "Rigid bodies: steps between rows of <output_dir>/bodies.csv (also at every output step and the last step)", NULL, r.interval, &r.interval, &flag));
  for (int k = 0; k < Config::kMaxBodies; ++k) {
    const std::string b = "-body" + std::to_string(k) + "_";
    BodySpec &B = r.bspec[k];
    GM_OPT(keep(b + "shape"), PetscOptionsString((b + "shape").c_str(), ("Kinematic rigid body k (0-3): " + names_list<BodyShape>() + " (disk: a cylinder along z in 3D; ring: solid outside -bodyK_radius)").c_str(), NULL, r.bshape[k], r.bshape[k], sizeof r.bshape[k], &r.bset[k]));
    if (!(r.bset[k] || k == 0)) continue;
    r.nbcenter[k] = r.nbhalf[k] = r.nbvel[k] = 3;
    for (int d = 0; d < 3; ++d) {
      r.bcenter[k][d] = B.center[d];
      r.bhalf[k][d] = B.half[d];
      r.bvel[k][d] = B.velocity[d];
    }
    GM_OPT(keep(b + "center"), PetscOptionsRealArray((b + "center").c_str(), "Body k: centre x,y[,z] [m] (plane: a point on it)", NULL, r.bcenter[k], &r.nbcenter[k], &flag));
    if (!flag) r.nbcenter[k] = 0;
    GM_OPT(keep(b + "radius"), PetscOptionsReal((b + "radius").c_str(), "Body k: radius of a disk or ring [m]", NULL, B.radius, &B.radius, &flag));
    GM_OPT(keep(b + "half"), PetscOptionsRealArray((b + "half").c_str(), "Body k: half extents hx,hy[,hz] of a box [m]", NULL, r.bhalf[k], &r.nbhalf[k], &flag));
    if (!flag) r.nbhalf[k] = 0;
    double deg = B.angle * 180.0 / M_PI;
    GM_OPT(keep(b + "angle"), PetscOptionsReal((b + "angle").c_str(), "Body k: initial rotation about z [degrees] (plane: direction of its outward normal, 0 = +x)", NULL, deg, &deg, &flag));
    B.angle = deg * M_PI / 180.0;
    GM_OPT(keep(b + "omega"), PetscOptionsReal((b + "omega").c_str(), "Body k: constant angular velocity about z through its centre [rad/s]", NULL, B.omega, &B.omega, &flag));
    GM_OPT(keep(b + "velocity"), PetscOptionsRealArray((b + "velocity").c_str(), "Body k: constant velocity vx,vy[,vz] [m/s]", NULL, r.bvel[k], &r.nbvel[k], &flag));
    if (!flag) r.nbvel[k] = 0;
    if (r.bcontact[k][0] == 0) std::strcpy(r.bcontact[k], "sticky");
    GM_OPT(keep(b + "contact"), PetscOptionsString((b + "contact").c_str(), "Body k: grid contact sticky (nodes take the body velocity)|friction (no penetration, Coulomb friction, separation allowed)", NULL, r.bcontact[k], r.bcontact[k], sizeof r.bcontact[k], &flag));
    GM_OPT(keep(b + "friction"), PetscOptionsReal((b + "friction").c_str(), "Body k: Coulomb friction coefficient of friction contact (>= 0)", NULL, B.friction, &B.friction, &flag));
    if (r.bmotion[k][0] == 0) std::strcpy(r.bmotion[k], "kinematic");
    GM_OPT(keep(b + "motion"), PetscOptionsString((b + "motion").c_str(), "Body k: kinematic (prescribed path/velocity and omega) | dynamic (moved by contact forces, gravity, applied force/torque)", NULL, r.bmotion[k], r.bmotion[k], sizeof r.bmotion[k], &flag));
    GM_OPT(keep(b + "path"), PetscOptionsString((b + "path").c_str(), "Body k (kinematic): piecewise-linear path of the centre, waypoints 't0,x0,y0[,z0];t1,x1,y1[,z1];...' with increasing t (instead of -bodyK_center/-bodyK_velocity)", NULL, r.bpath[k], r.bpath[k], sizeof r.bpath[k], &flag));
    GM_OPT(keep(b + "mass"), PetscOptionsReal((b + "mass").c_str(), "Body k (dynamic): mass [kg; 2D: kg per unit depth]", NULL, B.mass, &B.mass, &flag));
    if (flag) r.bdyn_opt[k] = b + "mass";
    GM_OPT(keep(b + "inertia"), PetscOptionsReal((b + "inertia").c_str(), "Body k (dynamic): moment of inertia about z through the centre [kg m^2; 2D: per unit depth] (default: a uniform disk/box of -bodyK_mass)", NULL, B.inertia, &B.inertia, &r.binertia_set[k]));
    if (r.binertia_set[k]) r.bdyn_opt[k] = b + "inertia";
    r.nbforce[k] = 3;
    GM_OPT(keep(b + "force"), PetscOptionsRealArray((b + "force").c_str(), "Body k (dynamic): applied force fx,fy[,fz] [N; 2D: N/m] (gravity acts as well)", NULL, r.bforce[k], &r.nbforce[k], &flag));
    if (flag) r.bdyn_opt[k] = b + "force";
    if (!flag) r.nbforce[k] = 0;
    GM_OPT(keep(b + "torque"), PetscOptionsReal((b + "torque").c_str(), "Body k (dynamic): applied torque about z [N m; 2D: N m/m]", NULL, B.torque, &B.torque, &flag));
    if (flag) r.bdyn_opt[k] = b + "torque";
    GM_OPT(keep(b + "damping"), PetscOptionsReal((b + "damping").c_str(), "Body k (dynamic): linear velocity damping rate [1/s] (>= 0)", NULL, B.damping, &B.damping, &flag));
    if (flag) r.bdyn_opt[k] = b + "damping";
    GM_OPT(keep(b + "angular_damping"), PetscOptionsReal((b + "angular_damping").c_str(), "Body k (dynamic): angular velocity damping rate [1/s] (>= 0)", NULL, B.angular_damping, &B.angular_damping, &flag));
    if (flag) r.bdyn_opt[k] = b + "angular_damping";
    GM_OPT(keep(b + "lock"), PetscOptionsString((b + "lock").c_str(), "Body k (dynamic): comma-separated degrees of freedom x,y,z,rot that keep the constant -bodyK_velocity/-bodyK_omega (none: all free)", NULL, r.block[k], r.block[k], sizeof r.block[k], &flag));
    if (flag) r.bdyn_opt[k] = b + "lock";
  }
  PetscFunctionReturn(0);
}

void BodyOptions::finish(Config &c) const {
  const Raw &r = *r_;
  c.body_contact_layer = r.contact_layer;
  c.bodies_interval = r.interval;
  for (int k = 0; k < Config::kMaxBodies; ++k) {
    if (!r.bset[k]) continue;
    const std::string b = "-body" + std::to_string(k) + "_";
    BodySpec B = r.bspec[k];
    B.shape = parse_name<BodyShape>(b + "shape", r.bshape[k]);
    B.contact = parse_name<BodyContact>(b + "contact", r.bcontact[k]);
    std::array<double, 3> tmp = B.center;
    read_vec((b + "center").c_str(), (int)r.nbcenter[k], r.bcenter[k], c.dim, tmp);
    B.center = tmp;
    tmp = B.half;
    read_vec((b + "half").c_str(), (int)r.nbhalf[k], r.bhalf[k], c.dim, tmp);
    B.half = tmp;
    tmp = B.velocity;
    read_vec((b + "velocity").c_str(), (int)r.nbvel[k], r.bvel[k], c.dim, tmp);
    B.velocity = tmp;
    tmp = B.force;
    read_vec((b + "force").c_str(), (int)r.nbforce[k], r.bforce[k], c.dim, tmp);
    B.force = tmp;
    if (c.dim == 2) B.center[2] = B.velocity[2] = B.force[2] = 0;
    B.motion = parse_name<BodyMotion>(b + "motion", r.bmotion[k]);
    parse_lock((b + "lock").c_str(), r.block[k], c.dim, B.lock);
    if (B.motion == BodyMotion::Kinematic && !r.bdyn_opt[k].empty()) bad(r.bdyn_opt[k] + " applies to dynamic bodies only: add " + b + "motion dynamic or remove it");
    if (r.bpath[k][0]) {
      B.path = parse_path((b + "path").c_str(), r.bpath[k], c.dim);
      if (r.nbcenter[k] || r.nbvel[k]) bad(b + "path gives the centre and its velocity: remove " + b + (r.nbcenter[k] ? "center" : "velocity"));
      if (B.motion == BodyMotion::Dynamic) bad(b + "path prescribes a kinematic body's motion: remove it or use " + b + "motion kinematic");
      for (int d = 0; d < 3; ++d) B.center[d] = B.path[0][1 + d];
    }
    if (B.motion == BodyMotion::Dynamic && !r.binertia_set[k]) B.inertia = uniform_inertia(B); // 0 for a plane or ring: validate() asks for it
    B.index = k;
    c.bodies.push_back(B);
  }
}

void BodyOptions::validate(const Config &c) {
  const char *axes = "xyz";
  const int dim = c.dim;
  const std::vector<BodySpec> &bodies = c.bodies;
  constexpr int kMaxBodies = Config::kMaxBodies;
  if (!(c.body_contact_layer >= 0 && c.body_contact_layer <= 2)) bad("-body_contact_layer must be in [0, 2] cells (got " + fmt(c.body_contact_layer) + ")");
  if (c.bodies_interval < 1) bad("-bodies_interval must be >= 1 (got " + std::to_string(c.bodies_interval) + ")");
  if ((int)bodies.size() > kMaxBodies) bad("at most " + std::to_string(kMaxBodies) + " rigid bodies (-body0_ .. -body3_)");
  for (size_t k = 0; k < bodies.size(); ++k) {
    const BodySpec &B = bodies[k];
    const std::string b = "-body" + std::to_string(B.index) + "_";
    if ((B.shape == BodyShape::Disk || B.shape == BodyShape::Ring) && !(B.radius > 0)) bad(b + "radius must be > 0 (got " + fmt(B.radius) + ")");
    if (B.shape == BodyShape::Box)
      for (int d = 0; d < dim; ++d)
        if (!(B.half[d] > 0)) bad(b + "half must be > 0 in every direction (got " + fmt(B.half[d]) + " in " + std::string(1, axes[d]) + ")");
    if (!(B.friction >= 0)) bad(b + "friction must be >= 0 (got " + fmt(B.friction) + ")");
    if (!std::isfinite(B.omega)) bad(b + "omega must be finite");
    if (B.path.size() == 1) bad(b + "path needs at least two waypoints");
    for (size_t i = 1; i < B.path.size(); ++i)
      if (!(B.path[i][0] > B.path[i - 1][0])) bad(b + "path: waypoint times must increase");
    if (B.motion == BodyMotion::Dynamic) {
      if (!B.path.empty()) bad(b + "path prescribes a kinematic body's motion: remove it or use " + b + "motion kinematic");
      if (!(B.mass > 0)) bad(b + "mass must be > 0 for a dynamic body (got " + fmt(B.mass) + ")");
      if (!B.lock[3] && !(B.inertia > 0))
        bad(b + "inertia must be > 0 for a dynamic body with free rotation (got " + fmt(B.inertia) + (B.shape == BodyShape::Plane || B.shape == BodyShape::Ring ? std::string("; a ") + name_of(B.shape) + " has no default" : std::string()) + "): give it, or " + b + "lock rot");
      if (!(B.damping >= 0)) bad(b + "damping must be >= 0 (got " + fmt(B.damping) + ")");
      if (!(B.angular_damping >= 0)) bad(b + "angular_damping must be >= 0 (got " + fmt(B.angular_damping) + ")");
    }
  }
}

void BodyOptions::signature(const Config &c, std::vector<std::pair<std::string, std::string>> &s) {
  const int dim = c.dim;
  const std::vector<BodySpec> &bodies = c.bodies;
  using opt::exact;
  auto vec = [dim](const std::array<double, 3> &a) { return opt::vec(a, dim); };
  for (const BodySpec &b : bodies) {
    const std::string k = "-body" + std::to_string(b.index) + "_";
    s.push_back({k + "shape", name_of(b.shape)});
    s.push_back({k + "center", vec(b.center)});
    s.push_back({k + "radius", exact(b.radius)});
    s.push_back({k + "half", vec(b.half)});
    s.push_back({k + "angle", exact(b.angle)});
    s.push_back({k + "omega", exact(b.omega)});
    s.push_back({k + "velocity", vec(b.velocity)});
    s.push_back({k + "contact", b.contact == BodyContact::Sticky ? "sticky" : "friction"});
    s.push_back({k + "friction", exact(b.friction)});
    s.push_back({k + "motion", b.motion == BodyMotion::Dynamic ? "dynamic" : "kinematic"});
    std::string path, lock;
    for (const auto &w : b.path) {
      path += path.empty() ? "" : ";";
      for (int d = 0; d <= dim; ++d) path += (d ? "," : "") + exact(w[d]);
    }
    const char *dofs[] = {"x", "y", "z", "rot"};
    for (int d = 0; d < 4; ++d)
      if (b.lock[d]) lock += (lock.empty() ? "" : ",") + std::string(dofs[d]);
    s.push_back({k + "path", path.empty() ? "none" : path});
    if (b.motion == BodyMotion::Dynamic) {
      s.push_back({k + "mass", exact(b.mass)});
      s.push_back({k + "inertia", exact(b.inertia)});
      s.push_back({k + "force", vec(b.force)});
      s.push_back({k + "torque", exact(b.torque)});
      s.push_back({k + "damping", exact(b.damping)});
      s.push_back({k + "angular_damping", exact(b.angular_damping)});
      s.push_back({k + "lock", lock.empty() ? "none" : lock});
    }
  }
}

} // namespace granmpm
