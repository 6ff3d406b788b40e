// HybridModule<dim>: the continuum/discrete coupling of issue 18 (docs/hybrid.md) with zones
// pinned geometrically (hybrid::FixedBand, -hybrid_band): mass splitting, the grains'
// weighted mass and momentum rasterised to the MPM grid, the per-node velocity constraint
// and the grains' FLIP-like update. It drives the DemModule's grains; no conversions.
//
// One MPM step of dt:
//   begin_step (DemModule)  the grains take their DEM sub-steps (contacts, gravity)
//   begin_grid              the owned grains' (m_D, p_D) to the nodes (tent weights), summed
//                           over the ranks like P2G (local-to-global ADD)
//   node                    at a node with both masses: lambda = (m_D p_M - m_M p_D)/(m_M + m_D)
//                           leaves the continuum (v_M -= lambda / m_M), kept for the grains
//   end_grid                lambda and m_D to the ghost nodes
//   end_step                each grain: v += sum_i w_i lambda_i / m_D,i (FLIP-like)
// Only the passes with forces are constrained (MUSL's remap and USF's first pass are not).
// sum_q m_q dv_q = sum_i lambda_i: the band's momentum is conserved to round-off.
#pragma once

#include <petscvec.h>

#include <cstdint>

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "granmpm/dem/module.hpp"
#include "granmpm/hybrid/coupling.hpp"

namespace granmpm {

template <int dim>
class HybridModule : public Module<dim> {
public:
  HybridModule(State<dim> &S, DemModule<dim> &grains, const hybrid::FixedBand &band);
  ~HybridModule() override;
  std::string name() const override { return "hybrid coupling"; }
  bool has_node_pass() const override { return true; }
  void begin_grid(State<dim> &S, double dt, bool with_force) override;
  void node(const NodeAt &n, double *v, double dt, bool with_force) override;
  void end_grid(State<dim> &S, double dt, bool with_force) override;
  void end_step(State<dim> &S, double dt) override;
  void rebuild(State<dim> &S) override;
  std::string summary() const override;
  // The zone oracle (-hybrid_zone_every N > 0): every N steps, phi of the grains and the
  // material points on a replicated copy of the MPM cells (summed over the ranks), the
  // signed distance and the zones; each grain and material point's zone is its cell's.
  // Diagnostic this step of issue 18: the mass shares still follow the fixed band.
  // drive: the zones set the mass shares (-hybrid_zone_every; docs/hybrid.md, "zones drive
  // the shares"); off: classification and counts only.
  struct Oracle {
    int every = 0; // 0: off
    double threshold = 0.3;
    hybrid::ZoneRule rule;
    bool drive = false;
    bool homogenise = false; // with drive: grains -> material points in cells continuum at two updates in a row
    bool enrich = false;     // with drive: material points -> grains in cells discrete at two updates in a row
  };
  void set_oracle(State<dim> &S, const Oracle &o);
  void update_zones(State<dim> &S);
  const std::vector<hybrid::Zone> &zones() const { return zones_; } // per cell, every rank
  const hybrid::CellGrid<dim> &zone_grid() const { return zgrid_; }
  // Over all ranks, after the last update: [0..2] material points per zone, [3..5] grains.
  const long *zone_counts() const { return zcount_; }
  long zone_updates() const { return zupdates_; }
  // Scales every material point's mass and volume by its continuum share (a fresh run) and
  // records it (and the zone) in the hybrid_weight / hybrid_zone fields when the swarm has them.
  static void split_particles(State<dim> &S, const hybrid::FixedBand &band);
  // The zone-driven shares (Oracle::drive, apply_shares: mass is handed from one species to
  // the other), over all ranks and the run: [0] material points whose mass changed, [1]
  // removed having given all of it to the grains, [2] grains whose mass changed, [3] removed
  // having given all of it to the material points.
  const long *share_counts() const { return shares_; }
  // The mass handed over by the share changes, over all ranks and the run: [0] material
  // points -> grains, [1] grains -> material points.
  const double *share_mass() const { return share_mass_; }
  // The change of the total mass (points + grains) over all zone updates of the run: round-off
  // (a zone update that changes it by more than 1e-11 relative throws).
  double mass_balance() const { return balance_; }
  // Homogenisation (Oracle::homogenise; called by update_zones after the shares): in every
  // cell that is continuum at this update and the one before, holds grains and no material
  // point, each grain becomes a material point at its centre with its (carried) mass and
  // velocity, the volume it fills at the cell's packing fraction (V_grain / phi) and the
  // cell's contact stress sum F (x) l / V_cell; the grains are removed. Mass and linear
  // momentum are conserved to round-off (the grains' spin is dropped). New ids:
  // kConvertedId + the grain's id. Collective.
  void homogenise(State<dim> &S);
  static constexpr int64_t kConvertedId = kConvertedParticleIds; // state.hpp
  // Enrichment (Oracle::enrich; after homogenise): in every cell that is discrete at this
  // update and the one before and holds material points, the points' mass M and momentum P
  // become grains of velocity P / M placed by hybrid::enrich_cell: n of one radius (n of them
  // weigh M exactly) on sub-cell centres clear of each other and of the grains already in
  // the cell and its neighbours (gathered from every rank) to -dem_overlap_tol, n from
  // floor(M / m(r)) (r the mean -dem_radius) down until they fit; if none does, grains of the
  // mean radius on the clear sites take part of M and the points keep the rest (their mass,
  // volume and share scaled, their velocity kept); a cell with no clear site is skipped
  // (counted). The points of a fully converted cell are removed. Mass and linear momentum are
  // conserved to round-off. Grain ids: kEnrichedId + (update, cell, j). Collective.
  void enrich(State<dim> &S);
  static constexpr int64_t kEnrichedId = int64_t(1) << 41;
  long enriched() const { return enr_[0]; }       // grains created over the run, all ranks
  long enriched_points() const { return enr_[1]; } // material points converted
  long enrich_skipped() const { return enr_[2]; }  // cells skipped
  long enrich_partial() const { return enr_[4]; }  // cells converted in part (their points keep the rest)
  long enrich_beside() const { return enr_[5]; }   // cells converted next to grains
  double enriched_mass() const { return enr_m_; }
  long homogenised() const { return homog_; }          // grains converted over the run, all ranks
  double homogenised_mass() const { return homog_m_; } // their mass
  void write_checkpoint(const State<dim> &S, CheckpointIO &io) const override;
  void read_checkpoint(State<dim> &S, CheckpointIO &io) override;
  long constrained_nodes() const { return constrained_; } // over the run, this rank
  double transferred() const { return transferred_; }     // sum of |lambda| over the run, this rank

private:
  DemModule<dim> &grains_;
  hybrid::FixedBand band_;
  const Grid<dim> *grid_ = nullptr;
  Vec glob_ = nullptr, loc_ = nullptr; // per node: m_D, p_D (dim), lambda (dim)
  PetscScalar *ga_ = nullptr;          // glob_'s owned array during the node pass
  bool active_ = false;
  long constrained_ = 0;
  double transferred_ = 0;
  double cpu_couple_ = 0, cpu_zones_ = 0; // this process's CPU seconds in the coupling's grid hooks and FLIP update, and in the zone updates
  std::string summary_;
  Oracle oracle_;
  hybrid::CellGrid<dim> zgrid_{};
  std::vector<hybrid::Zone> zones_;
  long zcount_[6] = {0, 0, 0, 0, 0, 0};
  long zupdates_ = 0, steps_ = 0;
  std::vector<double> has_mp_, has_grain_; // per cell at the last update: 1 where the species is present
  std::vector<double> phi_;                // per cell at the last update: the grains' packing fraction
  std::vector<hybrid::Zone> prev_;         // the zones of the update before
  long homog_ = 0, enr_[6] = {0, 0, 0, 0, 0, 0}; // grains made, points removed, cells skipped, points cut, cells in part, cells next to grains
  double enr_m_ = 0;
  double homog_m_ = 0;
  long shares_[4] = {0, 0, 0, 0};
  double share_mass_[2] = {0, 0};
  double balance_ = 0;
  void apply_shares(State<dim> &S);
  double total_mass(State<dim> &S); // collective
  hybrid::Zone zone_at(const double *x) const; // the oracle's zone of x's cell
  void make_vectors(const Grid<dim> &g);
  void destroy_vectors();
};

// -hybrid_dem and -hybrid_band: the DemModule and, with a band, the HybridModule of this
// MPM run (none without -hybrid_dem). The options are registered for -help either way.
template <int dim>
std::vector<std::unique_ptr<Module<dim>>> grain_modules(State<dim> &S);
// The DemModule of dc with the band's mass split and the HybridModule that couples it (the
// material points are split too on a fresh run); checks the grain size against the cell.
// The material points' fields the coupling writes (hybrid_weight, hybrid_zone) when the run
// couples (-hybrid_dem and -hybrid_band): registered by set-up before the swarm exists.
std::vector<std::pair<std::string, int>> hybrid_particle_fields(MPI_Comm comm);
template <int dim>
std::vector<std::unique_ptr<Module<dim>>> hybrid_modules(State<dim> &S, dem::Config dc, const hybrid::FixedBand &band);

} // namespace granmpm
