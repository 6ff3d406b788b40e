// The parallel DEM engine (issue 17; docs/dem.md). Grains (disks in 2D, spheres in 3D) live
// in a BASIC DMSwarm over a DMDA decomposition of the box; each rank owns the grains whose
// broad-phase cell it owns, keeps ghost copies of the grains within the interaction range of
// its subdomain, and computes the forces on its own grains from full, partner-id-sorted
// neighbour lists, so 1, 2 and 3 ranks give the same bits (contact.hpp explains why).
#pragma once

#include <petscdmda.h>
#include <petscdmswarm.h>
#include <hdf5.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

#include "granmpm/dem/contact.hpp"
#include "granmpm/dem/quaternion.hpp"
#include "granmpm/rigid_body.hpp"

namespace granmpm {
class CheckpointIO;
}

namespace granmpm::dem {

enum class RadiusDist { Mono = 0, Uniform = 1, Normal = 2 };
enum class Integrator { Verlet = 0, Euler = 1 };
enum class Scene { Block = 0, List = 1 };
enum class Lattice { Cubic = 0, Dense = 1 }; // dense: fcc (3D), hexagonal (2D)

struct Config {
  int dim = 3;
  std::array<double, 3> lo{0, 0, 0}, hi{1, 1, 1};
  std::array<bool, 3> periodic{false, false, false};
  std::array<std::array<bool, 2>, 3> outlet{}; // open faces [dim][lo/hi]: grains leave and are removed
  std::array<double, 3> gravity{0, 0, 0};
  // A horizontal plate (normal y) at plate_y with an orifice of width D centred at x (2D: a
  // slot; 3D: a round hole centred at x, z); off unless plate is set.
  bool plate = false;
  double plate_y = 0, orifice = 0, orifice_x = 0, orifice_z = 0;
  double density = 2500;      // grain material density [kg/m^3] (2D: per unit thickness)
  double radius = 0.01;       // mean radius [m]
  RadiusDist dist = RadiusDist::Mono;
  double spread = 0;          // uniform: half-width / radius; normal: sigma / radius
  ContactParams contact;      // grain-grain law
  ContactParams wall;         // grain-wall law (faces not periodic, the plate, rigid bodies)
  // Per-face friction and restitution over `wall` (NaN: wall's), indexed like the wall
  // entries: face 2k (lower) / 2k+1 (upper) of direction k, 2 dim the silo plate.
  std::array<double, 7> face_mu{NAN, NAN, NAN, NAN, NAN, NAN, NAN}, face_e{NAN, NAN, NAN, NAN, NAN, NAN, NAN};
  // The option naming face f (for -help and messages): xlo, xhi, ..., plate.
  std::string face_name(int f) const;
  double skin = 0;            // Verlet skin [m] (0: 0.3 radius)
  double cell = 0;            // broad-phase cell [m] (0: 2 r_max + skin)
  double dt = 0;              // 0: t_c / steps_per_contact
  double steps_per_contact = 20;
  Integrator integrator = Integrator::Verlet;
  double overlap_tol = 0.05;  // largest initial overlap / radius
  Scene scene = Scene::Block;
  std::array<double, 3> block_lo{0, 0, 0}, block_hi{1, 1, 1};
  double spacing = 0;         // nearest-neighbour lattice spacing (0: 2.02 r_max)
  Lattice lattice = Lattice::Cubic;
  double jitter = 0.0;        // lattice jitter / free gap (fraction)
  std::array<double, 3> v0{0, 0, 0};
  std::array<double, 3> w0{0, 0, 0}; // initial angular velocity of every grain (2D: about z)
  double vrand = 0;           // random velocity amplitude [m/s]
  uint64_t seed = 1;
  std::vector<double> grains; // List scene: x,y[,z],r,vx,vy[,vz] per grain
  // A host's mass split (hybrid band): the share of its mass a grain created at x carries
  // for life (inertia, contacts, gravity); empty: every grain carries all of it.
  std::function<double(const double *x)> mass_weight;
  double mass_weight_min = 1; // the smallest positive weight it gives (the contact time's lightest grain)
  double t_end = 0.1;
  long max_steps = -1;
  long output_every = 0;      // summary CSV row every n steps (0: 100 rows over the run)
  long fields_every = 0;      // HDF5+XDMF snapshot every n steps (0: first and last only)
  std::string output_dir = "output";
  bool output_overwrite = false; // replace an earlier run's results in output_dir
  bool fields = true;
  bool force_chains = false;  // snapshots also hold the contact network (chains_NNNNN.xmf, chains.xmf)
  // Keep and integrate each grain's orientation (3D quaternion, 2D angle) for snapshots and
  // checkpoints; nothing else reads it, so off changes no other result.
  bool orientation = true;
  bool quiet = false;
  std::string checkpoint;     // write at the end (and every checkpoint_every) to this file
  long checkpoint_every = 0;
  std::string restart;        // read state from this checkpoint
  // The standalone run's rigid bodies (-body<k>_*, rigid_body.hpp; a host gives its own
  // with Engine::set_bodies instead) and the steps between rows of bodies.csv.
  std::vector<BodySpec> bodies;
  long bodies_interval = 100;

  // Reads every -dem_* option (registered for -help); throws UserError on bad input.
  // check = false: leave validate() to the caller (a host sets the box first); bodies: also
  // read the -body<k>_* options (granmpm -dem).
  static Config from_options(MPI_Comm comm, bool check = true, bool bodies = false);
  void validate() const;
};

// One grain as gathered for tests and output.
struct GrainRecord {
  int64_t id;
  double x[3], v[3], w[3], r;
  int contacts;
  double hist_sum; // sum of |tangential spring| over the grain's contacts
  double m;        // mass as carried (weighted by Config::mass_weight)
  double q[4];     // orientation w, x, y, z (3D: integrated from the spin; 2D: from theta)
};

struct Summary {
  long step = 0;
  double t = 0, ke = 0, ke_rot = 0, pe_grav = 0, pe_elastic = 0;
  long contacts = 0, wall_contacts = 0, grains = 0, removed = 0;
  double removed_mass = 0; // of the grains that left through outlets (as carried)
  double coordination = 0, max_overlap = 0;
};

// A tangential spring kept across list rebuilds and migration: owner grain id a, partner
// key b (a grain id, or -(face+1) for a wall face).
struct HistRec {
  int64_t a, b;
  V3 h;
};

struct Timers {
  double neigh = 0, force = 0, comm = 0, integrate = 0;
  long rebuilds = 0;
};

// The decomposition of a host's grid (DemModule: the MPM's DMDA) used instead of the
// engine's own: P ranks per direction, the cut coordinates of each direction (P+1 values;
// the first and last are ignored in non-periodic directions), the host's owner-rank rule
// and the DM the swarm is attached to.
struct Partition {
  std::array<int, 3> P{1, 1, 1};
  std::array<std::vector<double>, 3> cut;
  std::function<int(const double *)> owner;
  DM cell_dm = nullptr;
};

struct CellBins; // the broad phase's cell binning (src/dem/internal.hpp)

// The state of this rank's grains at some step, kept in memory (a host's -on_instability
// backup): checkpoint rows and springs, clock and outlet counts.
struct Backup {
  std::vector<double> rows, hist;
  std::vector<double> body_prev; // the bodies' last contact forces (the same on every rank)
  double t = 0, removed_mass = 0;
  long step = 0, removed = 0;
};

class Engine {
public:
  Engine(MPI_Comm comm, const Config &cfg);
  ~Engine();
  Engine(const Engine &) = delete;
  Engine &operator=(const Engine &) = delete;

  void setup();           // creates grains (or reads the restart), builds lists, first forces
  void step() { own_bodies_ ? step_with_bodies() : step(dt_); } // one time step (with Config::bodies: they move too)
  void step(double dt);   // one step of dt (a host's sub-step; <= dt())
  // Host use (DemModule): set before setup(); repartition() migrates the grains with their
  // forces and springs to a new host decomposition (collective).
  void set_partition(Partition p) { part_ = std::move(p); }
  void repartition(Partition p);
  void set_gravity(const std::array<double, 3> &g) { c_.gravity = g; }
  const Config &config() const { return c_; }
  // The grains and springs in (from) a host's checkpoint, under "<prefix>grains", ...
  void write_state(CheckpointIO &io, const std::string &prefix) const;
  void read_state(CheckpointIO &io, const std::string &prefix);
  Backup backup() const;
  void restore(const Backup &b); // collective: every rank gets the grains it owns now
  int run();              // to t_end / max_steps with output; returns the stop signal (0: ran to the end)
  Summary summary();      // collective
  std::vector<GrainRecord> gather(); // id-sorted on rank 0 (empty elsewhere); collective
  void write_checkpoint(const std::string &path);
  void write_fields(int index);
  void write_xdmf(const std::string &base, long N); // rank 0
  double dt() const { return dt_; }
  long steps() const { return step_; }
  double time() const { return t_; }
  const Timers &timers() const { return tm_; }
  size_t bytes_per_grain() const;
  std::string footprint() const; // bytes per grain and where they go (two lines: categories, containers)
  struct Container {
    const char *name, *category; // category: state (owned grains), ghosts, lists, springs
    size_t bytes;
  };
  std::vector<Container> containers() const; // every container kept between steps
  double stress_moment(int k, double lo, double hi); // resident bytes per owned grain (state, ghosts, lists, store)
  long owned() const { return nown_; }
  // The owned grains for a host's coupling: positions, velocities (writable between steps),
  // masses as carried (weighted).
  const V3 *positions() const { return x_.data(); }
  V3 *velocities() { return v_.data(); }
  double mass(long i) const { return 1.0 / inv_mass(i); }
  double radius(long i) const { return r_[i]; }
  double mass_weight(long i) const { return mw_.empty() ? 1.0 : mw_[i]; } // the share of its mass a grain carries
  // The impulse the first half kick of the next step gives an owned grain (Verlet: h/2 f of
  // the last force pass, h the last sub-step; 0 otherwise): a host that removes the grain
  // (hybrid conversions) hands it over with the grain's momentum, since its contact partners
  // still take the opposite one.
  V3 pending_impulse(long i) const { return c_.integrator == Integrator::Verlet ? (0.5 * hstep_) * f_[i] : V3{0, 0, 0}; }
  std::vector<int64_t> gather_owned_ids() const { // this rank's, sorted
    std::vector<int64_t> ids(id_.begin(), id_.begin() + nown_);
    std::sort(ids.begin(), ids.end());
    return ids;
  }
  double contact_time_estimate() const { return tc_; }
  long chains_written() const { return chains_; } // lines in the last snapshot's contact network
  // A host's rigid bodies (rigid_body.hpp: plane, box, disk, ring) as contact partners of
  // the grains, with the wall law (-dem_wall_*; src/dem/bodies.cpp). set_bodies before
  // setup(); set_body_states at each host step: the state at host time t0 (kinematic
  // bodies then follow their path, dynamic ones move on at that velocity through the
  // step). take_body_impulse returns the impulse the grains gave each body since the last
  // call (fx, fy, fz, torque z; 4 per body), the same bits on every rank and rank count,
  // summed as the grains' own velocity updates take their forces (momentum conserved).
  void set_bodies(std::vector<BodySpec> specs, const std::vector<BodyMotionState> &start, double t0);
  void set_body_states(const std::vector<BodyMotionState> &start, double t0);
  // last (optional): the bodies' contact force of the last force pass (4 per body, reduced).
  std::vector<double> take_body_impulse(std::vector<double> *last = nullptr);
  size_t bodies() const { return bspec_.size(); }
  // Config::bodies (granmpm -dem): the engine moves them itself, each step (bodies.cpp);
  // their state at time() and the mean contact force over the last step (4 per body:
  // fx, fy, fz, torque z; the same on every rank).
  const std::vector<BodyMotionState> &body_states() const { return bst_; }
  const std::vector<double> &body_force() const { return bmean_; }
  void set_after_first_step(void (*f)(MPI_Comm)) { after_first_step_ = f; }
  // A host's zone update (hybrid, issue 18): the owned grains' new mass weights (w[i] > 0,
  // one per owned grain in the order of positions()) or their removal (w[i] == 0); the
  // forces and torques of the last step stay with their grains (the next half kick's),
  // ghosts get the new masses. Needs Config::mass_weight. Collective.
  void reweight(const std::vector<double> &w);
  // Per owned grain: the sum over its contacts (grains, walls, plate) of F (x) l, the contact
  // force on it times the branch vector from its centre to the contact, symmetrised (xx yy
  // zz xy yz xz): a region's Cauchy stress is the sum over its grains divided by its volume.
  std::vector<std::array<double, 6>> dipoles();
  // A host's conversion (hybrid enrichment): new owned grains (id, x, v, w, r; m as carried,
  // so the mass weight is m / the grain's full mass), placed by the host; forces, torques and
  // springs of the others are kept, the new ones start without. Collective.
  void add_grains(const std::vector<GrainRecord> &g);
  int64_t id(long i) const { return id_[i]; } // an owned grain's id

private:
  MPI_Comm comm_;
  Config c_;
  int rank_ = 0, size_ = 1;
  DM da_ = nullptr, sw_ = nullptr;
  std::array<int, 3> M_{1, 1, 1}, P_{1, 1, 1};
  std::array<std::vector<int>, 3> own_start_; // first cell of each rank column, size P+1
  double h_[3] = {1, 1, 1};
  double rmax_ = 0, halo_ = 0, dt_ = 0, t_ = 0;
  double hstep_ = 0; // the step being taken (dt_, or a host's sub-step)
  Partition part_;   // a host's decomposition (part_.owner set), else the own DMDA's
  long step_ = 0;
  int nrot_ = 3;

  // Working state between rebuilds: owned grains [0, nown) then ghosts [nown, ntot): first
  // the copies of other ranks' grains [nown, nd), then this rank's own periodic images
  // [nd, ntot), which keep no copy: their state is their owned grain's (dat), plus the shift.
  long nown_ = 0, ntot_ = 0, nd_ = 0;
  long self0_ = 0; // where this rank's own entries start in send_idx_: the images' grains
  long dat(long j) const { return j < nd_ ? j : send_idx_[self0_ + (j - nd_)]; } // the slot holding local grain j's state
  std::vector<V3> x_, v_, w_, f_, tq_, x0_;
  std::vector<double> r_, theta_; // theta_: the rotation angle of owned disks (2D only)
  std::vector<Quat> q_;                // the orientation of owned spheres (3D only; quaternion.hpp)
  // An owned grain's orientation as a quaternion (2D: the rotation by theta about z).
  // Without Config::orientation the arrays are empty and this is the identity.
  Quat orientation(long i) const {
    if (!c_.orientation) return Quat{};
    if (c_.dim == 3) return q_[i];
    return {std::cos(0.5 * theta_[i]), 0.0, 0.0, std::sin(0.5 * theta_[i])};
  }
  // Mass as carried, its inverse and the inverse moment of inertia, from the radius (and
  // the mass weight): derived, not stored (the same bits as a stored value).
  double mass_of(long i) const { return (mw_.empty() ? 1.0 : mw_[i]) * grain_mass(r_[i]); }
  double inv_mass(long i) const { return 1.0 / mass_of(i); }
  double inv_inertia(long i) const {
    const double m = mass_of(i);
    return 1.0 / ((c_.dim == 3 ? 0.4 : 0.5) * m * r_[i] * r_[i]);
  }
  // inv_mass and inv_inertia of the kBlock (or fewer) grains from i0, the same bits, in a
  // loop that vectorises the divisions (one per grain and kick cost a third of the kicks).
  static constexpr long kBlock = 256;
  void inverse_masses(long i0, long n, double *im, double *ii) const;
  std::vector<double> mw_; // mass weights (Config::mass_weight; empty without one)
  std::vector<char> drop_; // owned grains the next rebuild removes (reweight), not outlet losses
  std::vector<GrainRecord> add_; // grains the next rebuild adds (add_grains)
  std::vector<int64_t> id_;
  // Every local pair is evaluated once, by the grain first in the canonical order (ckey_,
  // id_) (ckey_: the broad-phase cell of the grain at the last rebuild, the same on every
  // rank); the partner gets the exactly negated force. ord_ lists the local grains (owned
  // and ghosts) in that order; the half lists (CSR over ord_ positions, ls_) hold the
  // partners later in the order (owned grains: any; ghosts: owned ones only) with their
  // tangential springs. Processing ord_ in turn, every grain sums its contacts in partner
  // order (walls first, then earlier partners as they push, then its own list): the same
  // order, hence the same bits, on every decomposition.
  std::vector<int> ckey_, ord_;
  std::vector<uint16_t> nl_; // list length per position in the order (the lists are walked in order: no CSR start)
  // List entries: partner j's local index, stored as ~j (negative) while the pair has a
  // spring. Springs exist only for touching pairs and are kept in pool_ in list order, so
  // an entry's spring is the next one of a walk over the lists (no slot index per entry);
  // the force pass rewrites the pool in place as contacts begin and end (pair_forces).
  std::vector<int> nb_;
  static int partner(int e) { return e < 0 ? ~e : e; }
  // Double precision: a quasi-static contact's slip per step (u_t dt ~ 1e-11 m) is about a
  // float ulp of its spring (~1e-4 m), so single-precision springs would round creep away
  // (docs/dem.md, memory).
  std::vector<V3> pool_;
  std::vector<V3> carry_; // the force pass's springs read ahead of an insertion (pair_forces)
  // Wall and plate contacts of owned grains, by owned index: the grain, face -(f+1), spring.
  std::vector<int> wg_, wf_;
  std::vector<V3> whist_;
  std::vector<uint16_t> ncontact_; // force-carrying contacts per owned grain (a grain has far fewer than 65536)
  // Ghost exchange plan (rebuilt with the lists): per destination rank, the owned indices
  // to send (to this rank itself: its periodic images); ghosts arrive in rank order.
  std::vector<int> send_idx_, send_cnt_, recv_cnt_;
  // The periodic shift of each ghost, as its index into the 27 possible shifts (one byte
  // instead of 24: each component is 0 or +-(hi - lo), the same bits either way).
  std::vector<uint8_t> gcode_;
  V3 shifts_[27];
  V3 gshift(long q) const { return shifts_[gcode_[q]]; }
  uint8_t shift_code(const V3 &s) const; // the index of shift s
  std::vector<V3> gbuf_send_;                             // per-step ghost update (x, v, omega per ghost sent to another rank)
  std::vector<int> gb_scnt_, gb_sdsp_, gb_rcnt_, gb_rdsp_; // its byte counts and offsets (receives: 1 of a type)
  std::vector<MPI_Datatype> gb_stype_, gb_rtype_;         // MPI_BYTE, and per source rank the ghosts' x, v, omega blocks
  const V3 *gb_x_ = nullptr, *gb_v_ = nullptr, *gb_w_ = nullptr; // the addresses the receive types were made for
  Timers tm_;
  void (*after_first_step_)(MPI_Comm) = nullptr;
  std::string series_; // XDMF grids written so far (rank 0)
  std::string chain_series_; // the same for the force chains
  double kick_ = 0;          // the last step's second half kick per unit im f (0.5 dt; 0: none since the forces)
  long write_chains(hid_t f, const std::string &path); // the contact network into a snapshot; returns the line count (collective)
  void write_chain_xdmf(const std::string &base, long C); // rank 0
  double tc_ = 0, elastic_ = 0, max_overlap_ = 0;
  long pair_entries_ = 0, wall_contacts_ = 0, removed_ = 0, chains_ = 0;
  double removed_mass_ = 0;
  V3 plate_point(const V3 &x) const; // closest point of the plate to x

  void create_swarm();
  void new_swarm();           // the swarm exists only from store_to_swarm to load_from_swarm
  int cell_key(const V3 &x) const;
  void set_keys();            // ckey_ of the owned grains from x0_ (positions at the rebuild)
  V3 pair_sep(long i, long j) const; // x_j - x_i with the periodic shifts of ghosts, bit-symmetric
  // The springs of touching contacts as seen from each owned grain (who: its local index).
  std::vector<HistRec> owned_springs(std::vector<long> *who) const;
  void create_grains();
  void load_from_swarm();
  void store_to_swarm();
  void rebuild();
  void rebuild_carrying_forces(bool new_grains); // rebuild(), keeping f, tq, contact counts
  template <class Want, class Fn> void contacts_at_rest(Want want, Fn fn); // forces.cpp only
  void exchange_ghosts_full();
  std::vector<std::vector<std::pair<int, V3>>> ghost_plan() const;
  void update_ghosts();
  void build_lists(bool first, const std::vector<HistRec> &store);
  double wall_lists(bool first, const std::vector<HistRec> &store);
  double pair_lists(bool first, const std::vector<HistRec> &store, const std::vector<V3> &xb, const CellBins &bins);
  double grain_mass(double r) const { return c_.dim == 3 ? c_.density * 4.0 / 3.0 * M_PI * r * r * r : c_.density * M_PI * r * r; }
  void compute_forces();
  struct Tally { // what a force pass adds up
    double elastic = 0, max_ov = 0;
    long contacts = 0, wall_contacts = 0;
  };
  void wall_forces(Tally &t);
  void pair_forces(Tally &t);
  int owner_rank(const V3 &x) const;
  V3 box_lo(int r) const;
  V3 box_hi(int r) const;
  void read_checkpoint(const std::string &path);
  double cut(int k, int p) const; // lower coordinate of rank column p in direction k
  // Checkpoint rows (CK_COLS per owned grain; 5 per spring) and their inverse (all rows).
  void pack_state(std::vector<double> &rows, std::vector<double> &hist) const;
  void unpack_state(const std::vector<double> &rows, const std::vector<double> &hist);
  std::vector<double> state_attr(long N, long H) const; // collective
  double grain_radius(int64_t id) const;
  void check_walls();
  // Rigid bodies (src/dem/bodies.cpp). Body k is wall entry face 2 dim + 1 + k.
  std::vector<BodySpec> bspec_;
  std::vector<BodyMotionState> bstart_, bnow_, blist_; // host state at bt0_, at the force pass, at the list build
  double bt0_ = 0;
  std::vector<double> bf_, bprev_, bimp_; // 4 per body: this pass's force, the last pass's, impulse since take (the whole sums, on every rank)
  std::array<ContactParams, 7> wlaw_; // the law of each face and the plate (Config::wall with its overrides)
  const ContactParams &wall_law(int face) const { return face <= 2 * c_.dim ? wlaw_[face] : c_.wall; }
  std::string body_msg_;                  // a grain found inside a body (reported at the next rebuild)
  void bodies_at(double t);               // bnow_ at time t
  double body_drift() const;              // bound on any body surface's move since the list build
  void body_lists(long i, std::vector<int> &faces, double &max_ov, bool first) const;
  // Wall entry `face` seen from a grain at xi: d = nearest partner point - xi, vw the partner's velocity there.
  V3 wall_sep(int face, const V3 &xi, V3 &vw) const;
  void body_reaction(int64_t id, int b, const V3 &xi, double ri, const V3 &d, const ContactResult &res);
  struct BodyHit { // the force (fx, fy, fz, torque z) of grain id's contact on body b
    int64_t id;
    int b;
    double f[4];
  };
  std::vector<BodyHit> bhits_; // this force pass's, on this rank
  void sum_body_hits();        // bf_ from every rank's hits, in (id, body) order (collective)
  void check_bodies(std::string &msg) const;
  // Config::bodies: the engine's own bodies (a standalone run).
  bool own_bodies_ = false;
  std::vector<BodyMotionState> bst_;  // at t_
  std::vector<double> blast_, bmean_; // the last pass's contact force, the last step's mean (4 per body, reduced)
  void own_bodies_setup();
  void step_with_bodies();
  void write_bodies_csv(bool force); // a row per body (rank 0), every Config::bodies_interval steps
  std::FILE *bcsv_ = nullptr;
  long bcsv_step_ = -1; // the step of the last row
};

// granmpm -dem ...: reads the options, runs, writes output; help_only: register and stop.
int run_main(MPI_Comm comm, bool help_only, void (*after_first_step)(MPI_Comm)); // the stop signal, or 0

} // namespace granmpm::dem
