#pragma once
// Synthetic response surfaces for the calibration tests: smooth functions of
// (theta, eta) shaped like the seed's Table 2.2, sampled on a grid with noise,
// as response surfaces or as stored task results in a database.
#include "calibrate/response_surface.hpp"
#include "db/store.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace demcal::test {

// phi_peak rises with both theta and eta; phi_cv rises with theta and saturates
// above about 25 deg (as in the seed, where phi_cv stays at 32-32.6 for theta >= 25).
inline double phi_peak_fn(double th, double eta) { return 18.0 + 0.55 * th + 30.0 * eta - 18.0 * eta * eta + 2.0 * std::sin(th / 9.0); }
inline double phi_cv_fn(double th, double eta) {
  return 32.3 - 9.0 * std::exp(-std::max(0.0, th - 5.0) / 6.0) + 6.0 * eta;
}
// A phi_cv that keeps rising with theta: with phi_peak it pins both parameters.
inline double phi_cv_steep(double th, double eta) { return 14.0 + 0.6 * th - 0.004 * th * th + 4.0 * eta; }
inline double phi_cv_flat(double th, double eta) { return 24.0 + 8.0 * (1.0 - std::exp(-th / 5.0)) + 3.0 * eta; }

using Fn = std::function<double(double, double)>;

inline const std::vector<double>& thetas() {
  static const std::vector<double> v = {15, 20, 25, 30, 35, 40};
  return v;
}
inline const std::vector<double>& etas() {
  static const std::vector<double> v = {0.0, 0.1, 0.2, 0.3, 0.4, 0.5};
  return v;
}

inline calibrate::ResponseSurface synthetic_surface(const Fn& f, double noise, int replicas, std::mt19937_64& rng,
                                                    const std::string& metric = "phi_peak") {
  std::normal_distribution<double> n01(0.0, 1.0);
  calibrate::ResponseSurface rs;
  rs.job = "synthetic";
  rs.metric = metric;
  rs.label = metric;
  rs.thetas = thetas();
  rs.etas = etas();
  for (double th : rs.thetas)
    for (double et : rs.etas) {
      calibrate::GridPoint p;
      p.theta = th;
      p.eta = et;
      for (int r = 0; r < replicas; ++r) p.values.push_back(f(th, et) + noise * n01(rng));
      rs.points.push_back(p);
    }
  rs.summarise();
  return rs;
}

// Two metrics of one job whose replica noise is correlated by rho, as phi_peak and
// phi_cv from the same packings are; each value carries its task id.
inline std::pair<calibrate::ResponseSurface, calibrate::ResponseSurface> synthetic_pair(
    const Fn& fa, const Fn& fb, double noise, double rho, int replicas, std::mt19937_64& rng) {
  std::normal_distribution<double> n01(0.0, 1.0);
  calibrate::ResponseSurface a, b;
  a.job = b.job = "synthetic";
  a.metric = a.label = "phi_peak";
  b.metric = b.label = "phi_cv";
  a.thetas = b.thetas = thetas();
  a.etas = b.etas = etas();
  std::int64_t task = 0;
  for (double th : a.thetas)
    for (double et : a.etas) {
      calibrate::GridPoint pa, pb;
      pa.theta = pb.theta = th;
      pa.eta = pb.eta = et;
      for (int r = 0; r < replicas; ++r) {
        const double z1 = n01(rng), z2 = n01(rng);
        pa.values.push_back(fa(th, et) + noise * z1);
        pb.values.push_back(fb(th, et) + noise * (rho * z1 + std::sqrt(1 - rho * rho) * z2));
        pa.tasks.push_back(++task);
        pb.tasks.push_back(task);
      }
      a.points.push_back(pa);
      b.points.push_back(pb);
    }
  a.summarise();
  b.summarise();
  return {a, b};
}

// A triaxial-like job stored through the store API: one task per grid point and
// replica, finished with phi_peak_deg, phi_cv_deg and q_peak_pa, except `failed`
// points (failed tasks) and `pending` points (never run).
struct FakePoint {
  double theta, eta;
};
inline void store_fake_job(db::Store& store, const std::string& name, const std::vector<double>& ths,
                           const std::vector<double>& ets, int replicas, double noise, std::uint64_t seed,
                           const std::vector<FakePoint>& failed = {}, const std::vector<FakePoint>& pending = {},
                           double confining_kpa = 100, double rho = 0,
                           const nlohmann::json& extra = nlohmann::json::object()) {
  std::vector<db::NewTask> tasks;
  for (double th : ths)
    for (double et : ets)
      for (int r = 0; r < replicas; ++r) {
        nlohmann::json p = {{"theta_deg", th}, {"eta", et}, {"seed", static_cast<int>(seed) + r}, {"confining_kpa", confining_kpa},
                            {"particles", 500}};
        p.update(extra);
        tasks.push_back({name + ":" + p.dump(), "triaxial", p.dump()});
      }
  nlohmann::json spec = {{"name", name}, {"scene", "triaxial"}, {"grid", {{"theta_deg", ths}, {"eta", ets}}}, {"replicas", replicas}};
  store.put_job(name, spec.dump(), tasks);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n01(0.0, 1.0);
  auto is_in = [](const std::vector<FakePoint>& v, double th, double et) {
    return std::any_of(v.begin(), v.end(), [&](const FakePoint& q) { return q.theta == th && q.eta == et; });
  };
  for (const auto& t : store.tasks(name)) {
    if (t.status != "pending") continue;
    const auto p = nlohmann::json::parse(t.params_json);
    const double th = p["theta_deg"], et = p["eta"];
    if (is_in(pending, th, et)) continue;
    store.claim(t.id, "test");
    db::Outcome o;
    if (is_in(failed, th, et)) {
      o.status = "failed";
      o.error = "synthetic failure";
    } else {
      o.status = "done";
      // phi_cv's noise correlated with phi_peak's by rho (one packing gives both).
      const double z1 = n01(rng), z2 = n01(rng);
      const double pk = phi_peak_fn(th, et) + noise * z1;
      const double cv = phi_cv_fn(th, et) + noise * (rho * z1 + std::sqrt(1 - rho * rho) * z2);
      const double s = std::sin(pk * M_PI / 180);
      const double q = confining_kpa * 1000 * (2 * s / (1 - s));  // sigma1 - sigma3 at phi_peak, no cohesion
      o.metrics = {{"phi_peak_deg", pk}, {"phi_cv_deg", cv}, {"q_peak_pa", q}};
    }
    store.finish(t.id, "test", o);
  }
}

}  // namespace demcal::test
