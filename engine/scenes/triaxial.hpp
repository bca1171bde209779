#pragma once
// Drained triaxial test of the seed's Sec. 2.2.3 (Figs. 2.7-2.12, Tables 2.2, 2.3).
//
// A polydisperse sample is generated without overlaps (random insertion at a low
// solid fraction) in a box of six smooth, rigid walls; z is the axial direction.
//
// Preparation (isotropic, every wall servo-held at p0, temporary local damping):
//  loose  "isotropic_compression": compression with the target theta, eta;
//  dense  "isotropic_compression": compression with theta = eta = 0 to p0 and
//         equilibrium (to prep_pressure_factor * p0, then "unloading" to p0); "stabilise": walls held still, target theta, eta switched
//         on, run until the unbalanced force ratio is small; "recompression":
//         servo compression to p0 and equilibrium again (the seed's three steps).
// Equilibrium = every wall's stress error below stress_tolerance and the
// unbalanced-force ratio below ufr_tolerance, on two consecutive checks (the
// frictionless "unloading" judges the walls only: the stabilise stage after it
// judges the ratio once friction is on). A stage
// that does not get there within its step budget ends the run: not_converged with
// the stage named, never a result.
//
// Deviatoric ("shear"): damping off (shear_damping > 0 is a diagnostic that leaves
// local damping on; not the seed's protocol, recorded and warned); top and bottom walls move at a constant
// engineering axial strain rate (relative to the height at the start of shear),
// lateral walls servo-held at sigma3 = p0, until the target axial strain.
//
// Sign conventions: compression positive for stresses and strains; strains are
// engineering strains from the lengths at the start of shear; eps_v = -dV/V0.
// sigma_i from walls: compressive normal force / current face area (face area from
// the current positions of the perpendicular walls). sigma1 = axial (z), sigma2 =
// x walls, sigma3 = y walls; phi_mob = asin((s1 - s3m)/(s1 + s3m)) with s3m the
// mean of the two lateral stresses.
#include "../material.hpp"
#include "../observer.hpp"
#include "../timestep.hpp"
#include "scene_status.hpp"

#include <cstdint>
#include <cmath>
#include <string>
#include <vector>

namespace demcal::engine {

// The seed's Table 2.1 with theta = 30 deg, b = 1, eta = 0.1.
Material triaxial_seed_material();

enum class Packing { dense, loose };
const char* to_string(Packing p);

struct TriaxialConfig {
  Material material = triaxial_seed_material();
  std::size_t particles = 2000;
  Packing packing = Packing::dense;
  double confining_pressure = 100e3;  // p0 [Pa]
  double strain_rate = 1e-4;          // axial, engineering [1/s]
  double axial_strain = 0.30;         // target eps1
  double shear_ramp_strain = 0.001;   // the axial rate ramps up linearly over this much eps1
  // Grain density for this quasi-static run. The seed scales the density up TO
  // 2.65e12 kg/m^3 (Sec. 2.2.3.1); density_scale > 0 instead multiplies
  // material.density by that factor (scaled_density is then ignored).
  double scaled_density = 2.65e12;
  double density_scale = 0.0;
  double aspect_ratio = 1.0;             // initial box height / width
  double initial_solid_fraction = 0.30;  // random insertion (<= 0.4)

  // Preparation
  double prep_damping = 0.3;          // local damping, preparation only (0: none)
  // Local damping left on in shear. The seed's Table 2.1 says none, and that is the
  // default; a value > 0 exists to measure how much a dissipation the seed does not
  // state would change phi_peak and phi_cv (docs/validation.md). Recorded, warned.
  double shear_damping = 0.0;
  // Dense step (i) compresses the frictionless sample to this multiple of p0, then
  // unloads it to p0 ("unloading"): stiff grains (Kn / (p0 d) = 2e5) rearrange
  // sqrt(factor) times faster in steps at the higher pressure; a frictionless
  // packing keeps its structure when unloaded. 1: straight to p0.
  double prep_pressure_factor = 100.0;
  long unloading_steps = 20000;       // geometric ramp of the unloading target, in steps of dt (simulated time: unloading_steps * dt)
  double prep_strain_rate = 0.02;     // wall speed cap in preparation, as (2 v / L) [1/s]
  double stress_tolerance = 0.01;     // |sigma_wall - p0| / p0 on every wall
  double ufr_tolerance = 0.01;        // unbalanced-force ratio
  long prep_step_budget = 400000;     // per preparation stage
  long stabilise_min_steps = 2000;    // dense step (ii): at least this many steps
  long check_interval = 250;          // steps between equilibrium checks

  // Servo walls
  double servo_alpha = 0.5;
  double servo_beta = 0.02;
  double shear_servo_strain_rate = 0.0;  // lateral wall speed cap in shear, as 2v/L; 0: 20 * strain_rate

  // Numerics
  double dt = 0.0;          // [s]; 0: dt_factor * sqrt(m_min / Kn), m_min after density scaling
  double dt_factor = 0.3;
  // Above this fraction of an isolated pair's critical step a dense packing may
  // jitter without settling (not_converged_context in triaxial.cpp, measured there).
  static constexpr double kJitterStepFraction = 0.5;
  // The step the run and validate suggest past it: this fraction of the critical step,
  // the default dt_factor's margin on the seed's material (0.3 of sqrt(m_min/Kn) = 0.41).
  static constexpr double kSuggestedStepFraction = 0.4;
  // Step of the dense preparation's frictionless stages (compression, unloading) as a
  // multiple of dt. 0: the ratio of the frictionless law's critical step to that of
  // the material's full law (tangential and rolling springs, the stiff modes the
  // frictionless law lacks, counted whatever theta and eta are): those stages run at
  // the same fraction of their own limit as the rest, about 1.96x for the seed's
  // material, the same for every task of a (theta, eta) grid. 1: dt throughout.
  double frictionless_dt_scale = 0.0;
  double max_overlap_fraction = 0.25;

  // Output
  double sample_strain = 0.001;              // series row every this much eps1
  long sample_steps = 0;                     // > 0: a row every this many shear steps instead
  double cv_from = 0.20, cv_to = 0.30;       // critical-state window of eps1
  // Whether a row at axial strain e1 is in that window. A row is taken on the first
  // shear step within half a step of its strain, so a row meant for an edge lies up to
  // half a step (`step_strain`, the axial strain of one shear step) on either side of
  // it: with a margin of 1e-9 the row meant for 0.20 was taken at 0.19999994 and left
  // out, and a window of [0.049, 0.05] held no row at all.
  bool in_cv_window(double e1, double step_strain) const {
    const double margin = 0.5 * step_strain + 1e-9;
    return e1 >= cv_from - margin && e1 <= cv_to + margin;
  }
  double quasi_static_inertial = 1e-3;       // warn above this inertial number
  // Beyond these the run is no drained triaxial test and ends invalid: the lateral
  // walls' mean stress error in shear (0.5: sigma3 half off p0 on average), and the
  // mean coordination number over the critical-state window (below 0.25, one contact
  // for eight grains: a collisional gas; the quick fidelity study's fast, small
  // samples, inertial number ~0.08, keep 0.4-0.5, and its 10x denser setting 0.04-0.15).
  double invalid_stress_error = 0.5;
  double invalid_coordination = 0.25;
  double dilatancy_window = 0.01;            // eps1 span of the dilatancy-angle difference
  // Critical state is shear without volume change at a steady stress ratio: the
  // window is judged by its dilatancy angle (from the slope of eps_v on eps1) and by
  // how far phi_mob drifts across it (when the drift is also > 2 of its standard errors).
  double cv_dilatancy_tolerance_deg = 5.0;
  double cv_drift_tolerance_deg = 2.0;

  std::uint64_t seed = 1;
  int threads = 1;

  void validate() const;  // throws ConfigError naming the field
  StepForecast step_forecast() const;  // for job validation (timestep.hpp)
  // Steps of the deviatoric stage: to axial_strain at strain_rate, the start-up ramp
  // taking twice its strain's time. The preparation's steps depend on how the packing
  // settles and are not forecast.
  double shear_steps() const;
  // How deep the preparation's walls, closing in at their speed cap
  // (prep_strain_rate * L0 / 2, L0 the initial box's side), press the largest grain
  // into a wall before its contact pushes back: v sqrt(m / kn), as a fraction of its
  // radius. The seed's material on 2,000 grains: 0.45%. 500 grains 2,700 times softer
  // blew up at 7.4% (three packings) and 15% (four tasks) and held at 3.7% and less.
  double prep_wall_impact_depth() const;
  // The prep_strain_rate at which that depth is `fraction` of max_overlap_fraction.
  double prep_strain_rate_for_impact(double fraction) const {
    return prep_strain_rate * fraction * max_overlap_fraction / prep_wall_impact_depth();
  }
  // Whether that depth is past kWallImpactNoted of the overlap limit (noted by validate,
  // said on a preparation's blow-up).
  bool prep_walls_too_fast() const { return prep_wall_impact_depth() > kWallImpactNoted * max_overlap_fraction; }
  // That depth said in words, with the rate that brings it to kWallImpactSuggested.
  std::string prep_wall_impact_words() const;
  static constexpr double kWallImpactNoted = 0.1;      // of max_overlap_fraction: said before the run and on a blow-up
  static constexpr double kWallImpactSuggested = 0.04;  // of max_overlap_fraction: what the suggested rate gives
  // The inertial number strain_rate * d_mean * sqrt(rho / p0) at the start of shear,
  // from the settings (d_mean of the material's grading): what the run's
  // quasi-static check will meet at least, known before it runs.
  double nominal_inertial_number() const;
  // kn / (p d_min): about the inverse of the overlap, in smallest diameters, a mean
  // stress p presses into a pair. Below kLowStiffnessNumber grains press deep into each
  // other under the load alone, whatever the step (the seed's material: 3e5 at 100 kPa,
  // 3000 in its dense preparation at 100 p0).
  double stiffness_number(double p) const { return material.kn / (p * material.d_min); }
  static constexpr double kLowStiffnessNumber = 1000.0;
  // What to change when kn / (p d_min) is below that: the dense preparation's extra
  // load first, where it has one.
  static const char* low_stiffness_remedy(bool prep_load_raised) {
    return prep_load_raised ? "lower triaxial.prep_pressure_factor or confining_kpa, or raise material.kn"
                            : "lower triaxial.confining_kpa or raise material.kn";
  }
  double grain_density() const { return density_scale > 0.0 ? material.density * density_scale : scaled_density; }
};

// How close a stage got to equilibrium when it ended.
struct StageReport {
  std::string name;
  bool converged = false;   // prep stages: the equilibrium test passed; shear: reached the strain
  long steps = 0;
  double time_s = 0;        // simulated
  double stress_error = 0;  // max over servo-held walls of |sigma - target| / target at the end (the stage's own target: 100 p0 in the dense compression)
  double ufr = 0;           // unbalanced-force ratio at the end
  double porosity = 0;      // at the end
  double mean_stress = 0;   // p from the walls at the end [Pa]
};

struct TriaxialResult {
  SceneOutcome outcome;

  // Metrics (meaningful only when outcome.ok())
  double phi_peak_deg = 0, eps1_at_peak = 0;
  // The peak of the stress ratio's centred 5-row running mean (0.5% of strain at the
  // default sampling): the maximum of noisy rows reads high by about the noise, the
  // more so the smaller the sample; the difference says how much.
  double phi_peak_smoothed_deg = NAN;
  static constexpr int kPeakSmoothingRows = 5;
  // A peak this far above the smoothed one rests on a spike of one or two rows (a
  // force chain against a wall that loads and buckles), not on the stress-strain
  // curve's hump: the run warns.
  static constexpr double kPeakTransientDeg = 2.0;
  // Series rows after the peak's row (0: the peak is the last row). The centred running
  // mean reaches no closer to the end than half its width (2 rows): there it cannot
  // tell a curve still rising (which peaks above its running mean by the rise) from a
  // spike, and the peak is not called one (the run says which it may be).
  int peak_rows_to_end = -1;
  // The rule, for a result here and for stored ones (calibrate): false on NaN. Without
  // rows_to_end (NaN: results stored before it was; -1: no row), judged by the angles alone.
  static bool peak_on_a_spike(double peak_deg, double smoothed_deg, double rows_to_end = NAN) {
    if (rows_to_end >= 0 && rows_to_end < kPeakSmoothingRows / 2) return false;
    return peak_deg - smoothed_deg > kPeakTransientDeg;
  }
  // phi_cv: the angle of the mean stress ratio over the window; its standard error
  // counts the rows' correlation (integrated autocorrelation time): the noise of this
  // run only, not the scatter between packings (replicas measure that).
  double phi_cv_deg = 0, phi_cv_se_deg = 0;
  // Fewer rows than this in the window (a coarse series, a short shear) judge nothing:
  // one row has a standard error of 0 and no trend, two a trend of their own noise.
  // phi_cv_se_deg is then NaN and the run says why.
  static constexpr int kMinWindowRows = 3;
  // A contact network this sparse over the window (whole-box mean coordination
  // number; a solid at critical state keeps 2 and more) is a collisional flow: warned.
  static constexpr double kSparseCoordination = 1.0;
  // NaN when not measured (an empty window; fewer than 3 rows for the fits): a 0
  // would read as a perfect critical state.
  double cv_effective_samples = NAN;  // window rows / (2 tau)
  double cv_dilatancy_deg = NAN;      // asin(-r / (2 - r)), r = d eps_v / d eps1 fitted over the window
  double cv_drift_deg = NAN, cv_drift_se_deg = NAN;  // change of phi_mob across the window, fitted
  // The same two angles from the interior Love-Weber stress (contact forces only).
  // They differ from the walls' where body forces carry load: local damping left on
  // in shear opposes the systematic deformation and holds part of the axial load.
  double phi_peak_interior_deg = 0, phi_cv_interior_deg = 0;
  int cv_samples = 0;
  // Mean grain-grain coordination number over the critical-state window (what the
  // invalid test reads), and the window's rows where the axial stress fell below the
  // lateral one (sigma1 < sigma3: extension, no compression test's state).
  double cv_coordination = NAN;
  int cv_rows_in_extension = 0;
  int cv_rows_unloaded = 0;  // rows where sigma1 = 0: the top and bottom walls lost the sample
  double q_peak = 0;                // [Pa]
  double porosity_initial = 0;      // after preparation (start of shear)
  double porosity_final = 0;
  double porosity_interior_initial = 0, porosity_interior_final = 0;  // of the Love-Weber volume
  double eps_v_final = 0;           // compression positive; dilation < 0
  double max_dilatancy_deg = 0;     // max of asin(-deps_v / (2 deps1 - deps_v))
  double max_inertial_number = 0;
  double lw_wall_mismatch = 0;      // |p_LW - p_walls| / p_walls at the start of shear
  // The interior's Love-Weber mean stress over the walls', averaged over the
  // critical-state window: below 1 where the layers along the walls carry more than
  // their share in shear (0.92 on 2,000 grains, 0.3% off at the start of shear).
  double lw_wall_ratio_cv = NAN;
  // Grains whose centres lie in the interior (the box less d_max from each wall), the
  // fewer of the start and the end of shear. Below kMinInteriorGrains the interior measures nothing: its
  // metrics above are NaN and a warning says why.
  long interior_grains = 0;
  static constexpr long kMinInteriorGrains = 20;
  bool interior_measured() const { return interior_grains >= kMinInteriorGrains; }
  double shear_stress_error_mean = 0, shear_stress_error_max = 0;  // lateral walls during shear

  // Set-up, recorded
  std::string packing;
  long particles = 0;
  double grain_density = 0, dt = 0, dt_critical = 0;
  std::string critical_mode;
  double dt_frictionless = 0;  // dense preparation's compression and unloading (0: loose, none)
  double d_mean = 0;
  bool local_damping_used = false;
  double prep_damping = 0;
  double shear_damping = 0;         // > 0: local damping during shear (diagnostic)
  bool walls_frictionless = true;   // the seed's walls are smooth: normal force only
  std::string walls;                // words
  double sample_size[3] = {0, 0, 0};  // box edges at the start of shear [m]
  std::vector<StageReport> stages;
  long steps = 0;
  double wall_seconds = 0;
  double cpu_seconds = 0;  // all threads (RunClock)
  int threads = 1;

  Series series;  // see the column list in triaxial.cpp
  Metrics metrics() const;
};

TriaxialResult run_triaxial(const TriaxialConfig& config, Observer* observer = nullptr);

// From a finished shear's series (columns eps1, z_all, sigma1, sigma2, sigma3): the
// critical-state window's coordination, rows in extension and rows with sigma1 = 0.
void judge_window(const TriaxialConfig& config, TriaxialResult& result);
// From those and the angles: why the run was no drained test (empty: it was one).
// run_triaxial ends such a run invalid in stage shear.
std::string why_invalid(const TriaxialConfig& config, const TriaxialResult& result);

// Whether the critical-state window's rows (eps1, eps_v, phi_mob in degrees) are at
// critical state: sets res.cv_dilatancy_deg and res.cv_drift_deg / _se_deg (from 3
// rows up) and adds a warning for a dilatancy angle beyond
// cfg.cv_dilatancy_tolerance_deg, a drift beyond cfg.cv_drift_tolerance_deg and twice
// its standard error, and res.cv_effective_samples below 4 (set it first).
void judge_critical_state(const TriaxialConfig& cfg, const std::vector<double>& eps1, const std::vector<double>& eps_v,
                          const std::vector<double>& phi_deg, TriaxialResult& res);

// Whether phi_peak is the curve's peak or a transient: warns when res.phi_peak_deg
// exceeds res.phi_peak_smoothed_deg by more than TriaxialResult::kPeakTransientDeg
// (nothing when the smoothed peak is not measured). Set both, eps1_at_peak and the
// interior's peak first.
void judge_peak(const TriaxialConfig& cfg, TriaxialResult& res);

}  // namespace demcal::engine
