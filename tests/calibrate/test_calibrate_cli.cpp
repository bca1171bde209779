// The calibration through the store and the demcal binary: maps with holes, fits
// stored in `fits`, refinement rounds, and the errors for bad input.
#include "calibrate/calibration.hpp"
#include "calibrate/map.hpp"
#include "synthetic.hpp"

#include "../cli/dist_util.hpp"

#include "jobs/job_error.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/query.hpp"
#include "jobs/runner.hpp"
#include "jobs/shard.hpp"

#include <gtest/gtest.h>

#include <csignal>
#include <iomanip>
#include <set>
#include <sstream>

namespace demcal::test {
namespace {

const std::vector<double> kTh = {15, 20, 25, 30, 35, 40};
const std::vector<double> kEt = {0.0, 0.1, 0.2, 0.3, 0.4, 0.5};

std::string make_db(const TempDir& d, bool with_holes = true) {
  const std::string path = d.file("demcal.db");
  db::Store s(path);
  if (with_holes)
    store_fake_job(s, "grid", kTh, kEt, 2, 0.3, 7, {{25, 0.3}, {40, 0.0}}, {{15, 0.5}});
  else
    store_fake_job(s, "grid", kTh, kEt, 2, 0.3, 7);
  return path;
}

// `demcal fit` with `extra` options and the synthetic angles at (th, et) as targets.
std::vector<std::string> fit_at(double th, double et, std::vector<std::string> extra = {}) {
  extra.insert(extra.begin(), "fit");
  extra.insert(extra.end(), {"--target", "phi_peak=" + std::to_string(phi_peak_fn(th, et)), "--target",
                             "phi_cv=" + std::to_string(phi_cv_fn(th, et))});
  return extra;
}

TEST(CalibrateStore, GatherAveragesReplicasAndKeepsHoles) {
  TempDir d;
  db::Store s(make_db(d));
  const auto rs = calibrate::gather(s, "grid", "phi_peak");
  EXPECT_EQ(rs.points.size(), 36u);
  EXPECT_EQ(rs.holes(), 3);
  EXPECT_EQ(rs.with_data(), 33);
  EXPECT_NEAR(rs.pooled_sd, 0.3, 0.15);
  for (const auto& p : rs.points) {
    if (p.theta == 25 && p.eta == 0.3) {
      EXPECT_EQ(p.failed, 2);
    }
    if (p.theta == 15 && p.eta == 0.5) {
      EXPECT_EQ(p.unfinished, 2);
    }
    if (!p.hole()) {
      EXPECT_EQ(p.n(), 2);
      EXPECT_NEAR(p.mean, phi_peak_fn(p.theta, p.eta), 1.5);
      EXPECT_TRUE(std::isfinite(p.se));
    }
  }
  const auto diff = calibrate::gather(s, "grid", "phi_diff");
  EXPECT_NEAR(diff.points[1].mean, phi_peak_fn(15, 0.1) - phi_cv_fn(15, 0.1), 1.5);
  EXPECT_THROW(calibrate::gather(s, "grid", "nonsense"), jobs::JobError);
  EXPECT_THROW(calibrate::gather(s, "nojob", "phi_peak"), jobs::JobError);
  EXPECT_THROW(calibrate::gather(s, "grid", "repose"), jobs::JobError);  // no data
}

// The task ids of a fake job's grid point, replica by replica.
std::vector<std::int64_t> point_tasks(const std::string& db, double th, double et) {
  db::Store s(db, true);
  std::vector<std::int64_t> ids;
  for (const auto& t : s.tasks("grid")) {
    const auto p = nlohmann::json::parse(t.params_json);
    if (p["theta_deg"] == th && p["eta"] == et) ids.push_back(t.id);
  }
  return ids;
}

// A point that lost one of its two replicas keeps a value, the other replica's: it is
// counted and named (fit, map), not passed off as a whole point. A grid node with no
// task in the database (a shard not merged) is a hole, as the map draws it.
TEST(CalibrateStore, APointShortOfReplicasAndANodeWithoutTasksAreSaid) {
  TempDir d;
  const std::string db = make_db(d, /*with_holes=*/false);
  const auto lost = point_tasks(db, 40, 0.0), absent = point_tasks(db, 25, 0.2), invalid = point_tasks(db, 15, 0.5);
  ASSERT_EQ(lost.size(), 2u);
  ASSERT_EQ(absent.size(), 2u);
  ASSERT_EQ(invalid.size(), 2u);
  sql(db, "UPDATE tasks SET status = 'failed', error = 'invalid in stage shear: the lateral walls lost sigma3' WHERE id IN (" +
              std::to_string(invalid[0]) + ", " + std::to_string(invalid[1]) + "); DELETE FROM metrics WHERE task_id IN (" +
              std::to_string(invalid[0]) + ", " + std::to_string(invalid[1]) + ")");
  sql(db, "UPDATE tasks SET status = 'failed' WHERE id = " + std::to_string(lost[1]) +
              "; DELETE FROM metrics WHERE task_id = " + std::to_string(lost[1]) +
              "; DELETE FROM job_tasks WHERE task_id IN (" + std::to_string(absent[0]) + ", " + std::to_string(absent[1]) + ")");
  {
    db::Store s(db, true);
    const auto rs = calibrate::gather(s, "grid", "phi_peak");
    EXPECT_EQ(rs.holes(), 2);
    EXPECT_EQ(rs.partials(), 1);
    EXPECT_EQ(rs.partial_list(), "theta 40, eta 0: 1 of 2 (1 failed)");
    for (const auto& p : rs.points) {
      if (p.hole()) {
        EXPECT_EQ(p.without_value(), p.theta == 15 ? "2 invalid (no test)" : "no task here: not in this database, or not selected")
            << p.theta;
      }
    }
  }
  Result r = run_demcal(fit_at(28, 0.22), d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("2 hole(s), 1 point(s) short of replicas"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("warning: 1 point(s) of job grid have a value from fewer replicas than they have tasks "
                       "(theta 40, eta 0: 1 of 2 (1 failed))"),
            std::string::npos)
      << r.out;
  r = run_demcal({"map", "--metric", "phi_cv", "--out", "m.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("2 hole(s), 1 short of replicas"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("hole: theta = 15, eta = 0.5 (2 invalid (no test))"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("hole: theta = 25, eta = 0.2 (no task here: not in this database, or not selected)"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("short of replicas: theta = 40, eta = 0 (the mean of 1; 1 failed)"), std::string::npos) << r.out;
  EXPECT_NE(slurp(d.file("m.svg")).find("short of replicas (failed or missing)"), std::string::npos);
  // A metric the tasks a filter selects do not store is no data there, not unknown.
  std::string seed8;
  for (const auto& t : db::Store(db, true).tasks("grid"))
    if (nlohmann::json::parse(t.params_json)["seed"] == 8) seed8 += (seed8.empty() ? "" : ", ") + std::to_string(t.id);
  sql(db, "DELETE FROM metrics WHERE name = 'phi_cv_deg' AND task_id IN (" + seed8 + ")");
  r = run_demcal({"map", "--metric", "phi_cv", "--where", "seed=8", "--out", "s.svg"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--metric: no data: none of job \"grid\"'s 35 selected tasks has a stored phi_cv_deg"),
            std::string::npos)
      << r.err;
  // A filter no task matches names the values its key takes.
  r = run_demcal({"map", "--metric", "phi_cv", "--where", "seed=99", "--out", "n.svg"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("has no tasks matching the filters: seed=99 matches no task; seed takes "), std::string::npos)
      << r.err;
}

// A map of one pressure draws the fit made on that pressure, never another's: a fit
// is drawn only on the --where pins it was made on, the newest by when it was made.
TEST(CalibrateCli, AMapDrawsOnlyAFitMadeOnItsPins) {
  TempDir d;
  const std::string db = d.file("demcal.db");
  {
    db::Store s(db);
    std::vector<db::NewTask> tasks;
    for (double p : {100.0, 200.0})
      for (double th : kTh)
        for (double et : kEt) {
          const nlohmann::json q = {{"theta_deg", th}, {"eta", et}, {"seed", 1}, {"confining_kpa", p}};
          tasks.push_back({"g:" + q.dump(), "triaxial", q.dump()});
        }
    s.put_job("g", R"({"name": "g"})", tasks);
    for (const auto& t : s.tasks("g")) {
      const auto q = nlohmann::json::parse(t.params_json);
      const double th = q["theta_deg"], et = q["eta"], shift = q["confining_kpa"] == 200.0 ? 1.0 : 0.0;
      s.claim(t.id, "test");
      db::Outcome o;
      o.status = "done";
      o.metrics = {{"phi_peak_deg", phi_peak_fn(th, et) + shift}, {"phi_cv_deg", phi_cv_fn(th, et) + shift}};
      s.finish(t.id, "test", o);
    }
  }
  auto fit = [&](const std::string& pin) {
    const Result r = run_demcal(fit_at(28, 0.22, {"--where", pin}), d.path.string());
    EXPECT_EQ(r.rc, 0) << r.err;
  };
  fit("confining_kpa=200");  // fit 1
  fit("confining_kpa=100");  // fit 2
  Result r = run_demcal({"map", "--metric", "phi_peak", "--where", "confining_kpa=200.0", "--out", "a.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("of job g (confining_kpa=200.0), 36 point(s)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("drawn: 95% region and best point of fit 1 "), std::string::npos) << r.out;
  EXPECT_NE(slurp(d.file("a.svg")).find("job g (confining_kpa=200.0): 36 points with data"), std::string::npos);
  r = run_demcal({"map", "--metric", "phi_peak", "--where", "confining_kpa=100", "--out", "b.svg"}, d.path.string());
  EXPECT_NE(r.out.find("drawn: 95% region and best point of fit 2 "), std::string::npos) << r.out;
  // A newer fit by its time (a merge copies an older one in under a higher id).
  fit("confining_kpa=200");  // fit 3
  sql(db, "UPDATE fits SET created_at = created_at + 1000 WHERE id = 1");
  r = run_demcal({"map", "--metric", "phi_peak", "--where", "confining_kpa=200", "--out", "c.svg"}, d.path.string());
  EXPECT_NE(r.out.find("drawn: 95% region and best point of fit 1 "), std::string::npos) << r.out;
  sql(db, "DELETE FROM fits WHERE id = 2");
  r = run_demcal({"map", "--metric", "phi_peak", "--where", "confining_kpa=100", "--out", "e.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(r.out.find("drawn: 95%"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("no fit drawn: job g's 2 fit(s) were made on other --where pins than this map's "
                       "(confining_kpa=100); a fit is drawn on the map of the pins it was made on"),
            std::string::npos)
      << r.out;
}

TEST(CalibrateMap, WritesPngAndSvgWithHoles) {
  TempDir d;
  db::Store s(make_db(d));
  const auto rs = calibrate::gather(s, "grid", "phi_peak");
  const auto sur = calibrate::fit_surrogate(rs);
  for (const char* name : {"m.png", "m.svg"}) {
    calibrate::MapRequest r;
    r.out = d.file(name);
    calibrate::draw_map(rs, sur, r);
    ASSERT_TRUE(fs::exists(r.out));
    EXPECT_GT(fs::file_size(r.out), 1000u);
  }
  // DEMCAL_KEEP_MAPS=DIR keeps the drawn maps for a look.
  if (const char* keep = std::getenv("DEMCAL_KEEP_MAPS"))
    for (const char* name : {"m.png", "m.svg"}) fs::copy_file(d.file(name), fs::path(keep) / name, fs::copy_options::overwrite_existing);
  const std::string svg = slurp(d.file("m.svg"));
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("holes (failed or missing)"), std::string::npos);
  calibrate::MapRequest bad;
  bad.out = d.file("m.pdf");
  EXPECT_THROW(calibrate::draw_map(rs, sur, bad), jobs::JobError);
}

// Too few points with data for a surface: the refusal says why the others have none.
TEST(CalibrateMap, TooFewPointsSaysWhyTheOthersHaveNone) {
  TempDir d;
  db::Store s(d.file("demcal.db"));
  store_fake_job(s, "few", {15, 20, 25}, {0.0, 0.1, 0.2}, 1, 0.3, 7,
                 {{15, 0.0}, {20, 0.0}, {25, 0.0}, {15, 0.1}, {20, 0.1}, {25, 0.1}}, {{15, 0.2}});
  const auto rs = calibrate::gather(s, "few", "phi_peak");
  try {
    calibrate::fit_surrogate(rs);
    FAIL() << "a surface on 2 points";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("needs at least 4 points with data, got 2 (7 grid point(s) have no data: their tasks 6 failed, "
                        "1 not finished; demcal status shows why tasks failed)"),
              std::string::npos)
        << what;
  }
}

// A metric with one value over the whole grid (a setting stored as a metric, a
// sample size that does not vary): gnuplot refused the empty colour range, and
// `map` exited 1 with gnuplot's own error about a script already deleted. It draws
// the flat map and says the value.
TEST(CalibrateMap, AMetricWithOneValueEverywhereDrawsAFlatMap) {
  TempDir d;
  db::Store s(make_db(d, false));
  // 500 grains; 2.65e12 kg/m^3, where a range of +-1 prints as one number.
  for (const auto& [value, shown] : std::vector<std::pair<double, std::string>>{{500.0, "500 everywhere"},
                                                                               {2.65e12, "2.65e+12 everywhere"}}) {
    auto rs = calibrate::gather(s, "grid", "phi_peak");
    for (auto& p : rs.points) {
      std::fill(p.values.begin(), p.values.end(), value);
      p.mean = value;
      p.sd = p.se = 0.0;
    }
    rs.pooled_sd = 0.0;
    const auto sur = calibrate::fit_surrogate(rs);
    calibrate::MapRequest r;
    r.out = d.file("flat.svg");
    ASSERT_NO_THROW(calibrate::draw_map(rs, sur, r)) << value;
    ASSERT_TRUE(fs::exists(r.out));
    EXPECT_NE(slurp(r.out).find(shown), std::string::npos) << value;
  }
}

// A grid point one of whose replicas takes phi_peak from a spike (5 deg above its
// running mean's peak) is marked on the phi_peak and phi_diff maps and listed with
// its replica count; the phi_cv map has nothing to mark.
TEST(CalibrateMap, APointWhosePeakRestsOnASpikeIsMarkedAndListed) {
  TempDir d;
  const std::string db = make_db(d, /*with_holes=*/false);
  {
    db::Connection c(db, /*read_only=*/false);
    c.exec("INSERT INTO metrics(task_id, name, value) SELECT task_id, 'phi_peak_smoothed_deg', value - 5 FROM metrics "
           "WHERE task_id = 6 AND name = 'phi_peak_deg'");
  }
  double th = 0, et = 0;
  {
    db::Store s(db, true);
    const auto rs = calibrate::gather(s, "grid", "phi_peak");
    int marked = 0;
    for (const auto& p : rs.points)
      if (p.spiked > 0) {
        ++marked, th = p.theta, et = p.eta;
        EXPECT_EQ(p.spiked, 1);
      }
    ASSERT_EQ(marked, 1);
  }
  std::ostringstream line;
  line << "peak on a spike: theta = " << th << ", eta = " << et << " (1 of 2 replica(s))";
  for (const char* metric : {"phi_peak", "phi_diff"}) {
    const auto r = run_demcal({"map", "--metric", metric, "--out", "m.svg"}, d.path.string());
    ASSERT_EQ(r.rc, 0) << r.out << r.err;
    EXPECT_NE(r.out.find(line.str()), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("--metric phi_peak_smoothed_deg maps the running mean's peak"), std::string::npos) << r.out;
    EXPECT_NE(slurp(d.file("m.svg")).find("phi_peak on a spike (in a replica)"), std::string::npos) << metric;
  }
  const auto cv = run_demcal({"map", "--metric", "phi_cv", "--out", "m.svg"}, d.path.string());
  ASSERT_EQ(cv.rc, 0) << cv.out << cv.err;
  EXPECT_EQ(cv.out.find("peak on a spike"), std::string::npos) << cv.out;
  EXPECT_EQ(slurp(d.file("m.svg")).find("phi_peak on a spike"), std::string::npos);
}

TEST(CalibrateMap, TitleIsTheUsersWhenGiven) {
  TempDir d;
  make_db(d, /*with_holes=*/false);
  auto r = run_demcal({"map", "--metric", "phi_peak", "--out", "m.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(slurp(d.file("m.svg")).find("surrogate: "), std::string::npos);
  r = run_demcal({"map", "--metric", "phi_peak", "--out", "m.svg", "--title", "Sand B, dense: φ_peak & <test>"},
                 d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string svg = slurp(d.file("m.svg"));
  EXPECT_NE(svg.find("Sand B, dense: φ_peak &amp; &lt;test"), std::string::npos) << svg;
  EXPECT_EQ(svg.find("surrogate: "), std::string::npos);
  // A newline would end gnuplot's title line: refused before anything is drawn.
  fs::remove(d.file("m.svg"));
  r = run_demcal({"map", "--metric", "phi_peak", "--out", "m.svg", "--title", "two\nlines"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--title: contains a control character"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("m.svg")));
}

TEST(CalibrateCli, FitPrintsTheAnswerAndStoresAFitRow) {
  TempDir d;
  const std::string db = make_db(d);
  const double th = 28, et = 0.22;
  const std::string pk = "phi_peak=" + std::to_string(phi_peak_fn(th, et)), cv = "phi_cv=" + std::to_string(phi_cv_fn(th, et));
  auto r = run_demcal({"fit", "--target", pk, "--target", cv}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("best: theta = "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("95% region"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("LOO RMS"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(" deg over "), std::string::npos) << r.out;  // the leave-one-out error has the angle's unit
  std::printf("%s", r.out.c_str());
  {
    db::Store s(db, true);
    const auto fits = s.fits();
    ASSERT_EQ(fits.size(), 1u);
    const auto j = nlohmann::json::parse(fits[0].result_json);
    EXPECT_EQ(j["status"], "ok");
    EXPECT_NEAR(j["theta_deg"].get<double>(), th, 3.0);
    EXPECT_NEAR(j["eta"].get<double>(), et, 0.05);
    EXPECT_EQ(nlohmann::json::parse(fits[0].targets_json).size(), 2u);
  }
  // The map now draws the fit's region.
  r = run_demcal({"map", "--metric", "phi_peak", "--out", "m.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("hole: theta = 25"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("95% region and best point of fit 1"), std::string::npos) << r.out;
  EXPECT_NE(slurp(d.file("m.svg")).find("95% region"), std::string::npos);
  if (const char* keep = std::getenv("DEMCAL_KEEP_MAPS")) {
    r = run_demcal({"map", "--metric", "phi_cv", "--out", "fit.png"}, d.path.string());
    fs::copy_file(d.file("fit.png"), fs::path(keep) / "fit.png", fs::copy_options::overwrite_existing);
  }
  // JSON output with a given sigma.
  r = run_demcal({"fit", "--target", pk, "--target", cv, "--sigma", "phi_peak=0.5", "--format", "json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["fit_id"], 2);
  // The stated sigma is the target's own; the surrogate's error adds to it.
  const auto& t0 = j["targets"][0];
  EXPECT_DOUBLE_EQ(t0["lab_sigma"].get<double>(), 0.5);
  const double ss = t0["surrogate_sigma"].get<double>();
  EXPECT_GT(ss, 0.0);
  EXPECT_NEAR(t0["sigma"].get<double>(), std::sqrt(0.25 + ss * ss), 1e-12);
  // A later fit on phi_peak alone: the phi_cv map keeps the latest fit that had a
  // phi_cv target, the phi_peak map takes the new one; each says what it inverted.
  r = run_demcal({"fit", "--target", pk}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  r = run_demcal({"map", "--metric", "phi_cv_deg", "--out", "cv.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("95% region and best point of fit 2 (targets phi_peak = "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(", phi_cv = "), std::string::npos) << r.out;
  EXPECT_NE(slurp(d.file("cv.svg")).find("95% region of fit 2, targets phi_peak = "), std::string::npos);
  EXPECT_NE(slurp(d.file("cv.svg")).find("phi_cv (deg)"), std::string::npos) << "a stored name gets the alias's label";
  r = run_demcal({"map", "--metric", "phi_peak", "--out", "pk.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("95% region and best point of fit 3 (targets phi_peak = "), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("phi_cv = "), std::string::npos) << r.out;
}

TEST(Calibrate, JobsFittedTogetherThatDoNotShareAMaterialAreNamed) {
  TempDir d;
  db::Store s(d.file("m.db"));
  const nlohmann::json sand = {{"kn", 3e7}, {"d_min", 0.001}}, soft = {{"kn", 1e7}, {"d_min", 0.001}};
  store_fake_job(s, "a", {20, 30}, {0.1, 0.2}, 1, 0.0, 1, {}, {}, 100, 0, sand);
  store_fake_job(s, "b", {20, 30}, {0.1, 0.2}, 1, 0.0, 2, {}, {}, 100, 0, soft);
  store_fake_job(s, "c", {25, 35}, {0.0, 0.3}, 1, 0.0, 3, {}, {}, 100, 0, sand);  // other grid, same material
  const std::string w = calibrate::material_mismatch(s, {"a", "b"});
  EXPECT_NE(w.find("do not share one material (kn: 30000000.0 (a) 10000000.0 (b))"), std::string::npos) << w;
  EXPECT_EQ(w.find("d_min"), std::string::npos) << w;
  // theta and eta are the grids' axes, not the material: jobs over other values agree.
  EXPECT_EQ(calibrate::material_mismatch(s, {"a", "c"}), "");
  EXPECT_EQ(calibrate::material_mismatch(s, {"a"}), "");
}

TEST(CalibrateCli, FitCountsTheReplicaCorrelationOfOneJobsMetrics) {
  TempDir d;
  {
    db::Store s(d.file("demcal.db"));
    store_fake_job(s, "grid", kTh, kEt, 3, 0.3, 7, {}, {}, 100, 0.7);
  }
  const double th = 28, et = 0.22;
  const std::string pk = "phi_peak=" + std::to_string(phi_peak_fn(th, et)), cv = "phi_cv=" + std::to_string(phi_cv_fn(th, et));
  auto r = run_demcal({"fit", "--target", pk, "--target", cv}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("replica correlation phi_peak ~ phi_cv: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("(72 dof over 36 points), counted in the misfit"), std::string::npos) << r.out;
  r = run_demcal({"fit", "--target", pk, "--target", cv, "--format", "json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["correlations"].size(), 1u);
  EXPECT_NEAR(j["correlations"][0]["rho"].get<double>(), 0.7, 0.2);
  EXPECT_TRUE(j["correlations"][0]["estimated"].get<bool>());
  // One replica a point: nothing to estimate, and the fit says so.
  TempDir one;
  {
    db::Store s(one.file("demcal.db"));
    store_fake_job(s, "grid", kTh, kEt, 1, 0.3, 7, {}, {}, 100, 0.7);
  }
  r = run_demcal({"fit", "--target", pk, "--target", cv}, one.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("not estimated (0 dof from paired replicas, fewer than 5): counted as 0"), std::string::npos) << r.out;
}

TEST(CalibrateCli, FitSaysWhenItsResultsCarryWarnings) {
  TempDir d;
  const std::string db = make_db(d, /*with_holes=*/false);
  const std::vector<std::string> args = fit_at(28, 0.22);
  auto r = run_demcal(args, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_EQ((r.out + r.err).find("carry warnings"), std::string::npos) << "clean results, no such warning";
  {
    db::Connection c(db, /*read_only=*/false);
    c.exec("UPDATE tasks SET error = 'warning: not quasi-static: test' WHERE id IN (1, 2, 3)");
    db::Store s(db, true);
    EXPECT_EQ(calibrate::gather(s, "grid", "phi_peak").warned, 3);
  }
  r = run_demcal(args, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("3 of the 72 results used from job grid carry warnings"), std::string::npos)
      << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("e.g.: not quasi-static: test"), std::string::npos) << r.out << r.err;
  EXPECT_EQ((r.out + r.err).find("not at critical state"), std::string::npos) << r.out << r.err;
  // The hint to see which queries the database the fit read, named unless it is the default.
  EXPECT_NE((r.out + r.err).find("(demcal query --job grid)"), std::string::npos) << r.out << r.err;
  fs::copy_file(db, d.path / "other.db");
  std::vector<std::string> other = args;
  other.insert(other.end(), {"--db", "other.db"});
  r = run_demcal(other, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("(demcal query --db other.db --job grid)"), std::string::npos) << r.out << r.err;
  // Two results whose phi_cv window was judged not at critical state: the phi_cv
  // surface says so by name, the phi_peak one does not.
  {
    db::Connection c(db, /*read_only=*/false);
    c.exec("UPDATE tasks SET error = 'warning: not at critical state over eps1 0.2-0.3: the sample still dilates; "
           "not quasi-static: test' WHERE id IN (4, 5)");
    db::Store s(db, true);
    EXPECT_EQ(calibrate::gather(s, "grid", "phi_cv").not_critical, 2);
    EXPECT_EQ(calibrate::gather(s, "grid", "phi_peak").not_critical, 0);
  }
  r = run_demcal(args, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("2 of the phi_cv results used from job grid come from a window the run judged not at "
                                 "critical state"),
            std::string::npos)
      << r.out << r.err;
  EXPECT_EQ((r.out + r.err).find("of the phi_peak results used"), std::string::npos) << r.out << r.err;
  // A map stands on the same results and says the same, in its output and its title.
  r = run_demcal({"map", "--metric", "phi_cv", "--out", "cv.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("warning: 2 of the phi_cv results used from job grid come from a window the run judged not at "
                       "critical state"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("warning: 5 of the 72 results used from job grid carry warnings"), std::string::npos) << r.out;
  EXPECT_NE(slurp(d.file("cv.svg")).find("5 result(s) warned"), std::string::npos);
  // One result whose phi_peak rests on a spike, judged from the stored values (a result
  // stored before the scene warned of spikes counts too): the phi_peak surface says so,
  // the phi_cv one does not. One 2 deg above its running mean is no spike.
  {
    db::Connection c(db, /*read_only=*/false);
    c.exec("INSERT INTO metrics(task_id, name, value) SELECT task_id, 'phi_peak_smoothed_deg', value - 5 FROM metrics "
           "WHERE task_id = 6 AND name = 'phi_peak_deg'");
    c.exec("INSERT INTO metrics(task_id, name, value) SELECT task_id, 'phi_peak_smoothed_deg', value - 2 FROM metrics "
           "WHERE task_id = 7 AND name = 'phi_peak_deg'");
    db::Store s(db, true);
    EXPECT_EQ(calibrate::gather(s, "grid", "phi_peak").on_spike, 1);
    EXPECT_EQ(calibrate::gather(s, "grid", "phi_diff").on_spike, 1);
    EXPECT_EQ(calibrate::gather(s, "grid", "phi_cv").on_spike, 0);
  }
  r = run_demcal(args, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("1 of the phi_peak results used from job grid take phi_peak from a spike of the "
                                 "walls' stress"),
            std::string::npos)
      << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("a target on phi_peak_smoothed_deg fits"), std::string::npos) << r.out << r.err;
  EXPECT_EQ((r.out + r.err).find("of the phi_cv results used from job grid take"), std::string::npos) << r.out << r.err;
}

TEST(CalibrateCli, UnreachableTargetExitsNonZeroNamingTheBound) {
  TempDir d;
  make_db(d);
  const auto r = run_demcal({"fit", "--target", "phi_peak=75", "--target", "phi_cv=30"}, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.out << r.err;
  EXPECT_NE(r.err.find("phi_peak = 75"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("upper bound"), std::string::npos) << r.err;
  EXPECT_EQ(r.out.find("best: theta ="), std::string::npos) << r.out;
}

TEST(CalibrateCli, SingleTargetWarns) {
  TempDir d;
  make_db(d);
  const auto r = run_demcal({"fit", "--target", "phi_peak=35"}, d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("warning: one target for two unknowns"), std::string::npos) << r.out;
}

TEST(CalibrateCli, FitRefusesWhatCannotGiveAnHonestRegion) {
  TempDir d;
  const std::string dir = d.path.string();
  {
    db::Store s(d.file("demcal.db"));
    store_fake_job(s, "two", {20, 30}, kEt, 2, 0.3, 7);
  }
  // Two theta values: a plane along theta, and a LOO error blind to its curvature.
  auto r = run_demcal({"fit", "--target", "phi_peak=35", "--target", "phi_cv=28"}, dir);
  EXPECT_EQ(r.rc, 2) << r.out;
  // No --job given: the job is demcal's choice, not a flag's fault, and is named.
  EXPECT_NE(r.err.find("error: job \"two\" has phi_peak at 2 theta value(s) (20, 30)"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("at least 3 of each"), std::string::npos) << r.err;
  r = run_demcal({"fit", "--target", "phi_peak=35", "--target", "phi_cv=28", "--job", "two"}, dir);
  EXPECT_EQ(r.rc, 2) << r.out;
  EXPECT_NE(r.err.find("--job: job \"two\" has phi_peak at 2 theta value(s)"), std::string::npos) << r.err;
  // phi_diff with both of its parts would count their residuals twice.
  TempDir d2;
  make_db(d2, false);
  r = run_demcal({"fit", "--target", "phi_peak=35", "--target", "phi_cv=28", "--target", "phi_diff=7"}, d2.path.string());
  EXPECT_EQ(r.rc, 2) << r.out;
  EXPECT_NE(r.err.find("--target: phi_diff is phi_peak - phi_cv"), std::string::npos) << r.err;
  // The same under the stored names, which the fit also takes.
  r = run_demcal({"fit", "--target", "phi_peak_deg=35", "--target", "phi_cv=28", "--target", "phi_diff=7"},
                 d2.path.string());
  EXPECT_EQ(r.rc, 2) << r.out;
  EXPECT_NE(r.err.find("--target: phi_diff is phi_peak_deg - phi_cv"), std::string::npos) << r.err;
  r = run_demcal({"fit", "--target", "phi_peak=35", "--target", "phi_cv=28", "--target", "phi_diff_deg=7"},
                 d2.path.string());
  EXPECT_EQ(r.rc, 2) << r.out;
  EXPECT_NE(r.err.find("phi_diff_deg"), std::string::npos) << r.err;
  // One metric under two names is one target given twice.
  r = run_demcal({"fit", "--target", "phi_peak=35", "--target", "phi_peak_deg=35"}, d2.path.string());
  EXPECT_EQ(r.rc, 2) << r.out;
  EXPECT_NE(r.err.find("--target: \"phi_peak\" and \"phi_peak_deg\" are the same stored metric (phi_peak_deg)"),
            std::string::npos)
      << r.err;
  // Two readings of one peak (raw and smoothed) are one sample's error, not two.
  r = run_demcal({"fit", "--target", "phi_peak=35", "--target", "phi_cv=28", "--target", "phi_peak_smoothed_deg=34"},
                 d2.path.string());
  EXPECT_EQ(r.rc, 2) << r.out;
  EXPECT_NE(r.err.find("--target: \"phi_peak\" and \"phi_peak_smoothed_deg\" read the same angle of the same runs"),
            std::string::npos)
      << r.err;
}

TEST(CalibrateCli, FitSearchesOnlyWhereThereIsDataAndNamesGaps) {
  TempDir d;
  {
    db::Store s(d.file("demcal.db"));
    std::vector<FakePoint> failed;
    for (double e : kEt) failed.push_back({40, e});  // the whole theta = 40 row failed
    failed.push_back({25, 0.3});
    store_fake_job(s, "grid", kTh, kEt, 2, 0.3, 7, failed);
  }
  const double th = 26, et = 0.27;  // near the failed point (25, 0.3)
  auto r = run_demcal(fit_at(th, et), d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("box: theta 15 .. 35 deg"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("warning: job grid has no phi_peak above theta 35"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("at a corner (theta 25, eta 0.3)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("phi_peak and phi_cv have no value at a corner"), std::string::npos) << r.out;
  // A region that reaches the cut box's edge (theta 35) stands on no cell beyond it:
  // the failed theta 40 row is no corner of the cells it lies on.
  r = run_demcal(fit_at(34.5, 0.1), d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("theta 35"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("theta 40, eta"), std::string::npos) << r.out;
}

TEST(CalibrateCli, BadInputNamesTheFieldAndExitsTwo) {
  TempDir d;
  const std::string dir = d.path.string();
  auto r = run_demcal({"fit", "--target", "phi_peak=40"}, dir);  // no database yet
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--db"), std::string::npos) << r.err;
  make_db(d);
  r = run_demcal({"fit", "--target", "phi_peek=40"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--target"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("unknown metric \"phi_peek\""), std::string::npos) << r.err;
  r = run_demcal({"fit", "--target", "phi_peak"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--target: expected METRIC=VALUE"), std::string::npos) << r.err;
  r = run_demcal({"fit", "--target", "phi_peak=4O"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("not a finite number"), std::string::npos) << r.err;
  r = run_demcal({"fit", "--target", "phi_peak=40", "--sigma", "phi_cv=1"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--sigma"), std::string::npos) << r.err;
  r = run_demcal({"fit", "--target", "repose=31"}, dir);  // a known metric nobody stored
  EXPECT_EQ(r.rc, 2);
  // The job's tasks are done and hold no repose angle: the metric is at fault, not a job.
  EXPECT_NE(r.err.find("error: --target: no data: none of job"), std::string::npos) << r.err;
  r = run_demcal({"map", "--metric", "repose"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("error: --metric: no data: none of job"), std::string::npos) << r.err;
  r = run_demcal({"fit", "--target", "phi_peak=40", "--job", "other"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--job: no job named \"other\""), std::string::npos) << r.err;
  r = run_demcal({"map", "--metric", "phi_pk"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--metric: unknown metric \"phi_pk\""), std::string::npos) << r.err;
  r = run_demcal({"map", "--metric", "phi_peak", "--out", "x.pdf"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out"), std::string::npos) << r.err;
  r = run_demcal({"map", "--metric", "phi_peak", "--where", "particles=9"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("no data"), std::string::npos) << r.err;
  // A job whose tasks never ran: no data.
  {
    db::Store s(d.file("demcal.db"));
    store_fake_job(s, "idle", kTh, kEt, 1, 0, 1, {}, [] {
      std::vector<FakePoint> all;
      for (double th : kTh)
        for (double et : kEt) all.push_back({th, et});
      return all;
    }());
  }
  r = run_demcal({"fit", "--target", "phi_peak=40", "--job", "idle"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("no data"), std::string::npos) << r.err;
  // One theta, two sample sizes: the missing grid is said first, not "pin particles".
  {
    db::Store s(d.file("demcal.db"));
    std::vector<db::NewTask> tasks;
    for (double et : {0.0, 0.1})
      for (int n : {500, 1000}) {
        const nlohmann::json p = {{"theta_deg", 30.0}, {"eta", et}, {"particles", n}, {"seed", 1}};
        tasks.push_back({"line:" + p.dump(), "triaxial", p.dump()});
      }
    s.put_job("line", "{}", tasks);
    for (const auto& t : s.tasks("line")) {
      s.claim(t.id, "test");
      db::Outcome o;
      o.status = "done";
      o.metrics = {{"phi_peak_deg", 40.0}};
      s.finish(t.id, "test", o);
    }
  }
  r = run_demcal({"fit", "--target", "phi_peak=40", "--job", "line"}, dir);
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("is not a (theta, eta) grid: it has 1 theta_deg and"), std::string::npos) << r.err;
}

TEST(CalibrateCli, ImpossibleTargetsAndPinnedAxesAreRefusedAndNothingIsStored) {
  TempDir d;
  const std::string dir = d.path.string();
  make_db(d);
  for (const char* t : {"phi_peak=-5", "phi_cv=95", "repose=90"}) {
    const auto r = run_demcal({"fit", "--target", t, "--target", "phi_diff=8"}, dir);
    EXPECT_EQ(r.rc, 2) << t;
    EXPECT_NE(r.err.find("is an angle in degrees: must lie in [0, 90)"), std::string::npos) << r.err;
  }
  const std::vector<std::pair<std::vector<std::string>, std::string>> refused = {
      {{"fit", "--target", "phi_peak=40", "--target", "phi_diff=95"}, "phi_diff is a difference of angles"},
      {{"fit", "--target", "phi_peak=40", "--where", "theta_deg=20"}, "--where: theta_deg is an axis of the surface"},
      {{"map", "--metric", "phi_peak", "--where", "eta=0.1"}, "--where: eta is an axis"},
      {{"fit", "--target", "phi_peak=40", "--sigma", "phi_peak"}, "(e.g. phi_peak=1.0)"},
      {{"fit", "--target", "phi_peak=40", "--sigma", "phi_peak=inf"}, "must be a positive finite number, got \"inf\""},
      {{"fit", "--target", "phi_peak=40", "--sigma", "phi_peak=1e200"}, "--sigma: sigma of phi_peak must be at most 1e100"},
      {{"fit", "--target", "phi_peak=40", "--sigma", "phi_peak=1", "--sigma", "phi_peak=2"},
       "--sigma: metric \"phi_peak\" given twice"},
      {{"fit", "--target", "phi_peak=40", "--job", "grid", "--job", "grid"}, "--job: \"grid\" given twice"},
  };
  for (const auto& [args, why] : refused) {
    const auto r = run_demcal(args, dir);
    EXPECT_EQ(r.rc, 2) << args[1] << " " << args[2];
    EXPECT_NE(r.err.find(why), std::string::npos) << r.err;
  }
  db::Store s(d.file("demcal.db"), /*read_only=*/true);
  EXPECT_TRUE(s.fits().empty());
}

// A database with a map drawn from it at m.png; returns the image.
std::string draw_good_map(const TempDir& d) {
  make_db(d, false);
  const auto r = run_demcal({"map", "--metric", "phi_peak", "--out", "m.png"}, d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
  return slurp(d.file("m.png"));
}

TEST(CalibrateCli, AFailedGnuplotLeavesTheEarlierMapWhole) {
  // A gnuplot that dies while drawing (killed, disk full) must not leave a broken
  // image where the user's good one was: the map is drawn beside it, then renamed.
  TempDir d;
  const std::string dir = d.path.string();
  const std::string good = draw_good_map(d);
  ASSERT_GT(good.size(), 1000u);
  // The stand-in runs the real gnuplot for scripts that draw nothing (the contour
  // tables) and, for the image, starts the file and fails.
  fs::create_directories(d.path / "bin");
  const std::string fake = (d.path / "bin" / "gnuplot").string();
  write(fake, "#!/bin/sh\n"
              "out=$(sed -n \"s/^set output '\\(.*\\)'$/\\1/p\" \"$1\")\n"
              "if [ -z \"$out\" ]; then PATH=" + std::string(std::getenv("PATH")) + " exec gnuplot \"$@\"; fi\n"
              "printf 'PNG' > \"$out\"\nexit 1\n");
  fs::permissions(fake, fs::perms::owner_all);
  const auto r = run_demcal({"map", "--metric", "phi_peak", "--out", "m.png"}, dir,
                            {{"PATH", (d.path / "bin").string() + ":" + std::getenv("PATH")}});
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("gnuplot failed"), std::string::npos) << r.err;
  EXPECT_EQ(slurp(d.file("m.png")), good);
  for (const auto& e : fs::directory_iterator(d.path))
    EXPECT_EQ(e.path().filename().string().find(".part"), std::string::npos) << e.path();
}

// A stand-in gnuplot that, for the image, starts a child of its own, records both
// pids and waits for ever; scripts that draw nothing go to the real gnuplot.
std::string hanging_gnuplot(const TempDir& d) {
  fs::create_directories(d.path / "bin");
  const std::string fake = (d.path / "bin" / "gnuplot").string();
  write(fake, "#!/bin/sh\n"
              "out=$(sed -n \"s/^set output '\\(.*\\)'$/\\1/p\" \"$1\")\n"
              "if [ -z \"$out\" ]; then PATH=" + std::string(std::getenv("PATH")) + " exec gnuplot \"$@\"; fi\n"
              "printf 'PNG' > \"$out\"\n"
              "sleep 1000 &\necho $! > " + d.file("child.pid") + "\n"
              "echo $$ > " + d.file("gnuplot.pid.part") + "\nmv " + d.file("gnuplot.pid.part") + " " +
              d.file("gnuplot.pid") + "\nwait\n");
  fs::permissions(fake, fs::perms::owner_all);
  fs::create_directories(d.path / "tmp");
  return (d.path / "bin").string() + ":" + std::getenv("PATH");
}

bool process_gone(const std::string& pid_file) {
  const int pid = std::stoi(slurp(pid_file));
  for (int i = 0; i < 200 && kill(pid, 0) == 0; ++i) usleep(10000);  // an orphan is reaped by init
  return kill(pid, 0) != 0;
}

// What a stopped gnuplot must leave: the earlier map, no part file, no scratch
// folder, and neither gnuplot nor the child it started still running.
void expect_nothing_left(const TempDir& d, const std::string& good) {
  EXPECT_EQ(slurp(d.file("m.png")), good);
  for (const auto& e : fs::directory_iterator(d.path))
    EXPECT_EQ(e.path().filename().string().find(".png.part"), std::string::npos) << e.path();
  EXPECT_TRUE(fs::is_empty(d.path / "tmp"));
  EXPECT_TRUE(process_gone(d.file("gnuplot.pid")));
  EXPECT_TRUE(process_gone(d.file("child.pid")));
}

TEST(CalibrateCli, AGnuplotThatHangsIsStoppedAtItsTimeLimit) {
  TempDir d;
  const std::string dir = d.path.string();
  const std::string good = draw_good_map(d);
  ASSERT_GT(good.size(), 1000u);
  const std::string path = hanging_gnuplot(d);
  auto r = run_demcal({"map", "--metric", "phi_peak", "--out", "m.png"}, dir,
                 {{"PATH", path}, {"TMPDIR", (d.path / "tmp").string()}, {"DEMCAL_GNUPLOT_TIMEOUT_S", "5"}});
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("gnuplot did not finish within 5 s"), std::string::npos) << r.err;
  ASSERT_TRUE(fs::exists(d.file("gnuplot.pid"))) << "the image's gnuplot never started: " << r.err;
  expect_nothing_left(d, good);
  r = run_demcal({"map", "--metric", "phi_peak", "--out", "m.png"}, dir, {{"DEMCAL_GNUPLOT_TIMEOUT_S", "soon"}});
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("DEMCAL_GNUPLOT_TIMEOUT_S: must be a positive number of seconds, got 'soon'"), std::string::npos)
      << r.err;
}

TEST(CalibrateCli, SigtermWhileGnuplotDrawsStopsItAndLeavesNothingBehind) {
  for (const int sig : {SIGTERM, SIGINT}) {
    TempDir d;
    const std::string dir = d.path.string();
    const std::string good = draw_good_map(d);
    ASSERT_GT(good.size(), 1000u);
    const std::string path = hanging_gnuplot(d);
    const pid_t pid = spawn({"map", "--metric", "phi_peak", "--out", "m.png"}, dir,
                            {{"PATH", path}, {"TMPDIR", (d.path / "tmp").string()}});
    for (int i = 0; i < 3000 && !fs::exists(d.file("gnuplot.pid")); ++i) usleep(10000);
    ASSERT_TRUE(fs::exists(d.file("gnuplot.pid")));
    kill(pid, sig);
    const Result r = finish(pid, dir);
    EXPECT_EQ(r.rc, 1) << r.err;
    EXPECT_NE(r.err.find(sig == SIGTERM ? "terminated (SIGTERM) while gnuplot was drawing"
                                        : "interrupted (SIGINT) while gnuplot was drawing"),
              std::string::npos)
        << r.err;
    expect_nothing_left(d, good);
  }
}

// Several jobs named with --job: each target comes from the one job that stores it.
TEST(CalibrateCli, JobsNamedForAFitEachGiveTheirOwnMetrics) {
  TempDir d;
  {
    db::Store s(d.file("demcal.db"));
    store_fake_job(s, "g1", kTh, kEt, 1, 0.0, 1);
    store_fake_job(s, "g2", kTh, kEt, 1, 0.0, 2);
    std::vector<FakePoint> all;  // a job whose tasks all failed: it stores no metric
    for (double th : kTh)
      for (double et : kEt) all.push_back({th, et});
    store_fake_job(s, "dead", kTh, kEt, 1, 0.0, 3, all);
  }
  const std::string dir = d.path.string();
  auto with = [&](std::vector<std::string> jobs) {
    std::vector<std::string> named;
    for (const auto& j : jobs) named.insert(named.end(), {"--job", j});
    return run_demcal(fit_at(26, 0.2, named), dir);
  };
  // Both named jobs store phi_peak: the advice is to name one of them, not "use --job".
  auto r = with({"g1", "g2"});
  EXPECT_EQ(r.rc, 2) << r.out;
  EXPECT_NE(r.err.find("--job: phi_peak is stored by more than one of the jobs named (g1, g2)"), std::string::npos)
      << r.err;
  // A named job that gives no target is said, not silently dropped.
  r = with({"g1", "dead"});
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("warning: job dead (--job) stores none of the targets' metrics: the fit does not use it"),
            std::string::npos)
      << r.out;
  r = with({"g1"});
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(r.out.find("stores none of the targets"), std::string::npos) << r.out;
}

TEST(CalibrateCli, EnvelopeAcrossConfiningPressures) {
  TempDir d;
  {
    db::Store s(d.file("demcal.db"));
    // Same (theta, eta) grid at three pressures, merged into one job.
    for (double p : {50.0, 100.0, 200.0})
      store_fake_job(s, "mc" + std::to_string(static_cast<int>(p)), {20, 30}, {0.1, 0.2}, 1, 0.0, 3, {}, {}, p);
    std::vector<db::NewTask> all, two;
    for (const auto& name : {"mc50", "mc100", "mc200"})
      for (const auto& t : s.tasks(name)) {
        all.push_back({t.key, t.scene, t.params_json});
        if (std::string(name) != "mc200") two.push_back(all.back());
      }
    s.put_job("mc", "{}", all);
    s.put_job("mc2", "{}", two);
  }
  // Two peaks a point: the line fits them exactly and has no standard error, said so
  // (it printed "+- nan").
  const auto pair = run_demcal({"envelope", "--job", "mc2"}, d.path.string());
  ASSERT_EQ(pair.rc, 0) << pair.err;
  EXPECT_EQ(pair.out.find("nan"), std::string::npos) << pair.out;
  EXPECT_NE(pair.out.find("+- n/a"), std::string::npos) << pair.out;
  EXPECT_NE(pair.out.find("n/a: the line through two tests"), std::string::npos) << pair.out;
  const auto r = run_demcal({"envelope", "--job", "mc"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  std::printf("%s", r.out.c_str());
  // Zero cohesion by construction: phi equals phi_peak of the point, c about 0.
  std::istringstream in(r.out);
  std::string line;
  std::getline(in, line);
  double th = 0, et = 0, phi = 0, c = 0;
  int n = 0, p = 0;
  std::string pm;
  double se = 0;
  ASSERT_TRUE(std::getline(in, line));
  std::istringstream ls(line);
  ls >> th >> et >> n >> p >> phi >> pm >> se >> c;
  EXPECT_EQ(p, 3);
  EXPECT_NEAR(phi, phi_peak_fn(th, et), 1e-3);
  EXPECT_NEAR(c, 0.0, 1e-3);
  EXPECT_EQ(r.out.find("warning:"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("left out"), std::string::npos) << r.out;
  // A peak that failed is named with its reason, the peaks used that carry warnings
  // are counted, and a cohesion the grains cannot have is said.
  const std::string db = d.file("demcal.db");
  std::int64_t failed = 0, warned = 0;
  // The point whose sigma1 all rise by 50 kPa: a line with an intercept; and one whose
  // sigma1 all fall by 30 kPa: a negative intercept, a tension. Written as the angles
  // the envelope reads, sin phi = (s1 - s3) / (s1 + s3).
  std::string moved;
  auto angle_sql = [&](std::int64_t id, double s3, double phi_point, double ds1) {
    const double s1 = s3 * (1 + std::sin(phi_point * M_PI / 180)) / (1 - std::sin(phi_point * M_PI / 180)) + ds1;
    const double moved_phi = std::asin((s1 - s3) / (s1 + s3)) * 180 / M_PI;
    moved += "UPDATE metrics SET value = " + std::to_string(moved_phi) + " WHERE name = 'phi_peak_deg' AND task_id = " +
             std::to_string(id) + "; ";
  };
  for (const auto& t : db::Store(db, true).tasks("mc")) {
    const auto q = nlohmann::json::parse(t.params_json);
    const double theta = q["theta_deg"], eta = q["eta"], p0 = q["confining_kpa"];
    if (theta == 20 && eta == 0.2) angle_sql(t.id, p0, phi_peak_fn(theta, eta), -30.0);
    if (theta == 20 && eta == 0.1 && p0 == 50.0) failed = t.id;
    if (theta == 30 && eta == 0.1 && p0 == 100.0) angle_sql(t.id, p0, phi_peak_fn(theta, eta), 10.0);  // off the line
    if (theta == 30 && eta == 0.2) {
      angle_sql(t.id, p0, phi_peak_fn(theta, eta), 50.0);
      if (p0 == 200.0) warned = t.id;
    }
  }
  sql(db, "UPDATE tasks SET status = 'failed', error = 'invalid in stage shear: the lateral walls lost sigma3' WHERE id = " +
              std::to_string(failed) + "; UPDATE tasks SET error = 'warning: not quasi-static: fast' WHERE id = " +
              std::to_string(warned) + "; " + moved);
  const auto bad = run_demcal({"envelope", "--job", "mc"}, d.path.string());
  ASSERT_EQ(bad.rc, 0) << bad.err;
  EXPECT_NE(bad.out.find("left out at theta 20, eta 0.1: 50 kPa: task " + std::to_string(failed) +
                         " failed: invalid in stage shear: the lateral walls lost sigma3"),
            std::string::npos)
      << bad.out;
  EXPECT_NE(bad.out.find("warning: 1 of the 11 peaks used carry warnings"), std::string::npos) << bad.out;
  EXPECT_NE(bad.out.find("warning: theta 30, eta 0.2: cohesion "), std::string::npos) << bad.out;
  EXPECT_NE(bad.out.find("warning: theta 20, eta 0.2: cohesion -"), std::string::npos) << bad.out;
  EXPECT_NE(bad.out.find("a negative c is a tension"), std::string::npos) << bad.out;
  // One test a pressure, one of them off the line: the errors rest on one degree of
  // freedom, and the interval is Student's.
  EXPECT_NE(bad.out.find("warning: theta 30, eta 0.1: the errors with cohesion rest on 1 degree(s) of freedom (3 tests, "
                         "2 parameters): a 95% interval is 12.706 standard errors either side"),
            std::string::npos)
      << bad.out;
  // The critical-state envelope reads phi_cv_deg, which the tampering above left alone.
  const auto cv = run_demcal({"envelope", "--job", "mc", "--state", "cv"}, d.path.string());
  ASSERT_EQ(cv.rc, 0) << cv.err;
  EXPECT_NE(cv.out.find("from its phi_cv_deg"), std::string::npos) << cv.out;
  EXPECT_EQ(cv.out.find(": cohesion"), std::string::npos) << cv.out;
  const auto wrong = run_demcal({"envelope", "--job", "mc", "--state", "residual"}, d.path.string());
  EXPECT_EQ(wrong.rc, 2) << wrong.out;
  // One pressure only: no line with cohesion, but the secant angle, which is the
  // point's phi_peak (one test a point: no error).
  const auto one = run_demcal({"envelope", "--job", "mc50"}, d.path.string());
  ASSERT_EQ(one.rc, 0) << one.err;
  EXPECT_NE(one.out.find("n/a (one pressure)"), std::string::npos) << one.out;
  EXPECT_NE(one.out.find("one pressure: a line with cohesion takes two; phi at c = 0 is then the tests' secant angle"),
            std::string::npos)
      << one.out;
  {
    std::ostringstream row;
    row << std::fixed << std::setprecision(3) << phi_peak_fn(30, 0.1);
    EXPECT_NE(one.out.find(row.str()), std::string::npos) << row.str() << " not in:\n" << one.out;
  }
  // A filter that matches nothing says so, not "no data".
  const auto none = run_demcal({"envelope", "--job", "mc", "--where", "theta_deg=99"}, d.path.string());
  EXPECT_EQ(none.rc, 2);
  EXPECT_NE(none.err.find("--where: no task of job \"mc\" matches"), std::string::npos) << none.err;
  // The envelope's own axis pinned: said so, not "needs two confining pressures".
  const auto axis = run_demcal({"envelope", "--job", "mc", "--where", "confining_kpa=100"}, d.path.string());
  EXPECT_EQ(axis.rc, 2);
  EXPECT_NE(axis.err.find("--where: confining_kpa is the envelope's axis"), std::string::npos) << axis.err;
}

TEST(CalibrateRefine, RoundsConvergeOnTheTruthAndAreRecorded) {
  TempDir d;
  const std::string db = d.file("demcal.db");
  db::Store s(db);
  // A coarse grid; refinement runs add exact values where asked.
  store_fake_job(s, "coarse", {15, 25, 35, 45}, {0.0, 0.2, 0.4, 0.6}, 1, 0.0, 1);
  const double th = 31.3, et = 0.27;
  calibrate::FitRequest req;
  req.targets = {{"phi_peak", phi_peak_fn(th, et)}, {"phi_cv", phi_cv_fn(th, et)}};
  calibrate::Calibration cal = calibrate::calibrate(s, req);
  calibrate::store_fit(s, req, cal, 0);
  const double err0 = std::abs(cal.result.theta - th) / 30 + std::abs(cal.result.eta - et) / 0.6;
  calibrate::RefineOptions ro;
  ro.rounds = 4;
  ro.tolerance = 0.01;
  std::ostringstream log;
  ro.log = &log;
  int calls = 0;
  ro.run_points = [&](db::Store& st, const std::string& job, int round, const std::vector<calibrate::RefinePoint>& pts) {
    ++calls;
    std::vector<double> ths, ets;
    for (const auto& p : pts) ths.push_back(p.theta), ets.push_back(p.eta);
    std::sort(ths.begin(), ths.end());
    ths.erase(std::unique(ths.begin(), ths.end()), ths.end());
    std::sort(ets.begin(), ets.end());
    ets.erase(std::unique(ets.begin(), ets.end()), ets.end());
    store_fake_job(st, calibrate::refine_job_name(job, round), ths, ets, 1, 0.0, 1);
  };
  const auto rounds = calibrate::refine(s, req, cal, ro);
  ASSERT_FALSE(rounds.empty());
  const double err1 = std::abs(cal.result.theta - th) / 30 + std::abs(cal.result.eta - et) / 0.6;
  std::printf("refine: %zu round(s); error before %.4g, after %.4g; %s", rounds.size(), err0, err1, log.str().c_str());
  EXPECT_EQ(calls, static_cast<int>(rounds.size()));
  EXPECT_LE(err1, err0 + 1e-9);
  EXPECT_NEAR(cal.result.theta, th, 1.0);
  EXPECT_NEAR(cal.result.eta, et, 0.03);
  EXPECT_EQ(s.fits().size(), rounds.size() + 1);
  const auto last = nlohmann::json::parse(s.fits().back().result_json);
  EXPECT_EQ(last["round"], static_cast<int>(rounds.size()));
  EXPECT_TRUE(last["refine"].contains("move"));
  // The refinement points are part of the surface now.
  const auto rs = calibrate::gather(s, "coarse", "phi_peak");
  int refine_points = 0;
  for (const auto& p : rs.points) refine_points += p.refine;
  EXPECT_GT(refine_points, 0);
  EXPECT_EQ(rs.thetas.size(), 4u);  // the job's own axes are unchanged
}

// A small collision job over (theta, eta, ...): milliseconds a task, enough to run
// refinement rounds through the real jobs runner.
nlohmann::json small_collision_job(const std::string& name, const nlohmann::json& grid) {
  return {{"name", name},
          {"scene", "collision"},
          {"material", {{"kn", 3e7}, {"diameter", {{"min", 0.001}, {"max", 0.002}}}}},
          {"collision", {{"particles", 20}, {"steps", 100}, {"sample_every", 20}}},
          {"grid", grid},
          {"seed", 1},
          {"threads", 1}};
}

// A fake DEM: the points' theta x eta grid stored as the round's sub-job.
calibrate::PointRunner fake_point_runner(std::vector<std::pair<int, std::vector<calibrate::RefinePoint>>>& calls) {
  return [&calls](db::Store& st, const std::string& job, int round, const std::vector<calibrate::RefinePoint>& pts) {
    calls.emplace_back(round, pts);
    std::set<double> ths, ets;
    for (const auto& p : pts) ths.insert(p.theta), ets.insert(p.eta);
    store_fake_job(st, calibrate::refine_job_name(job, round), {ths.begin(), ths.end()}, {ets.begin(), ets.end()}, 1,
                   0.0, 1);
  };
}

bool has_point(const calibrate::ResponseSurface& rs, double th, double et) {
  return std::any_of(rs.points.begin(), rs.points.end(),
                     [&](const calibrate::GridPoint& p) { return p.theta == th && p.eta == et && !p.hole(); });
}

// A coarse grid, the targets of (31.3, 0.27), and options for one new round whose
// runs a fake DEM stores (tolerance 0: every asked round runs).
class RefineRounds : public ::testing::Test {
 protected:
  TempDir d;
  db::Store s{d.file("demcal.db")};
  calibrate::FitRequest req;
  std::vector<std::pair<int, std::vector<calibrate::RefinePoint>>> calls;
  std::ostringstream log;
  calibrate::RefineOptions ro;

  void SetUp() override {
    store_fake_job(s, "coarse", {15, 25, 35, 45}, {0.0, 0.2, 0.4, 0.6}, 1, 0.0, 1);
    req.targets = {{"phi_peak", phi_peak_fn(31.3, 0.27)}, {"phi_cv", phi_cv_fn(31.3, 0.27)}};
    ro.rounds = 1;
    ro.tolerance = 0;
    ro.log = &log;
    ro.run_points = fake_point_runner(calls);
  }
  // Round `round` of an earlier invocation, cut short: one of its four runs never ran.
  void store_unfinished_round(int round) {
    store_fake_job(s, calibrate::refine_job_name("coarse", round), {30, 35}, {0.2, 0.3}, 1, 0.0, 1, {}, {{35, 0.3}});
  }
};

TEST_F(RefineRounds, ALaterInvocationNumbersOnAndKeepsTheEarlierRounds) {
  calibrate::Calibration cal = calibrate::calibrate(s, req);
  ASSERT_EQ(calibrate::refine(s, req, cal, ro).size(), 1u);
  // Another invocation, other targets: its round is 2, and round 1 stays in the job.
  req.targets = {{"phi_peak", phi_peak_fn(38.0, 0.45)}, {"phi_cv", phi_cv_fn(38.0, 0.45)}};
  cal = calibrate::calibrate(s, req);
  const auto second = calibrate::refine(s, req, cal, ro);
  ASSERT_EQ(second.size(), 1u);
  EXPECT_EQ(second[0].round, 2);
  EXPECT_FALSE(second[0].resumed);
  ASSERT_EQ(calls.size(), 2u);
  EXPECT_EQ(calls[0].first, 1);
  EXPECT_EQ(calls[1].first, 2);
  EXPECT_EQ(calibrate::refine_jobs_of(s, "coarse"), (std::vector<std::string>{"coarse.refine1", "coarse.refine2"}));
  const auto rs = calibrate::gather(s, "coarse", "phi_peak");
  for (const auto& call : calls)
    for (const auto& p : call.second) EXPECT_TRUE(has_point(rs, p.theta, p.eta)) << p.theta << ", " << p.eta;
  // The second invocation's spacing starts again from the grid's / 2 (10 deg / 2).
  std::set<double> ths;
  for (const auto& p : calls[1].second) ths.insert(p.theta);
  ASSERT_EQ(ths.size(), 2u);
  EXPECT_NEAR(*ths.rbegin() - *ths.begin(), 5.0, 1e-3);
  EXPECT_EQ(nlohmann::json::parse(s.fits().back().result_json)["round"], 2);
}

TEST_F(RefineRounds, AnUnfinishedRoundIsFinishedBeforeNewOnes) {
  store_unfinished_round(1);
  std::vector<std::string> resumed;
  ro.resume_round = [&](db::Store& st, const std::string& sub) {
    resumed.push_back(sub);
    for (const auto& t : st.tasks(sub)) {
      if (t.status != "pending") continue;
      ASSERT_TRUE(st.claim(t.id, "test"));
      const auto p = nlohmann::json::parse(t.params_json);
      db::Outcome o;
      o.status = "done";
      o.metrics = {{"phi_peak_deg", phi_peak_fn(p["theta_deg"], p["eta"])}, {"phi_cv_deg", phi_cv_fn(p["theta_deg"], p["eta"])}};
      st.finish(t.id, "test", o);
    }
  };
  calibrate::Calibration cal = calibrate::calibrate(s, req);
  const auto rounds = calibrate::refine(s, req, cal, ro);
  EXPECT_EQ(resumed, std::vector<std::string>{"coarse.refine1"});
  ASSERT_EQ(rounds.size(), 2u) << log.str();
  EXPECT_TRUE(rounds[0].resumed);
  EXPECT_EQ(rounds[0].round, 1);
  EXPECT_TRUE(rounds[0].points.empty());
  EXPECT_EQ(rounds[1].round, 2);
  ASSERT_EQ(calls.size(), 1u);
  EXPECT_EQ(calls[0].first, 2);
  EXPECT_TRUE(has_point(calibrate::gather(s, "coarse", "phi_peak"), 35, 0.3));
  const auto fits = s.fits();
  ASSERT_EQ(fits.size(), 2u);
  const auto first = nlohmann::json::parse(fits[0].result_json);
  EXPECT_EQ(first["round"], 1);
  EXPECT_EQ(first["refine"]["resumed"], nlohmann::json::array({"coarse.refine1"}));
  EXPECT_NE(log.str().find("resuming round 1 of job coarse (1 run(s) unfinished)"), std::string::npos) << log.str();
  // A finished round is not resumed again.
  resumed.clear();
  cal = calibrate::calibrate(s, req);
  calibrate::refine(s, req, cal, ro);
  EXPECT_TRUE(resumed.empty());
  EXPECT_EQ(calls.back().first, 3);
}

// A repose-like job: one task per point, finished with repose_deg.
void store_fake_repose(db::Store& st, const std::string& name, const std::vector<double>& ths,
                       const std::vector<double>& ets) {
  std::vector<db::NewTask> tasks;
  for (double th : ths)
    for (double et : ets) {
      const nlohmann::json p = {{"theta_deg", th}, {"eta", et}, {"seed", 1}};
      tasks.push_back({name + ":" + p.dump(), "repose", p.dump()});
    }
  const nlohmann::json spec = {{"name", name}, {"scene", "repose"}, {"grid", {{"theta_deg", ths}, {"eta", ets}}}};
  st.put_job(name, spec.dump(), tasks);
  for (const auto& t : st.tasks(name)) {
    const auto p = nlohmann::json::parse(t.params_json);
    ASSERT_TRUE(st.claim(t.id, "test"));
    db::Outcome o;
    o.status = "done";
    o.metrics = {{"repose_deg", 10.0 + 0.4 * p["theta_deg"].get<double>() + 20.0 * p["eta"].get<double>()}};
    st.finish(t.id, "test", o);
  }
}

TEST(CalibrateRefine, ARoundCutShortBeforeAJobRunsItsPointsThere) {
  TempDir d;
  db::Store s(d.file("demcal.db"));
  const std::vector<double> ths = {15, 25, 35, 45}, ets = {0.0, 0.2, 0.4, 0.6};
  store_fake_job(s, "tri", ths, ets, 1, 0.0, 1);
  store_fake_repose(s, "rep", ths, ets);
  // Round 1 ran for "rep" (first by name) and was cut off before "tri".
  store_fake_repose(s, "rep.refine1", {30, 35}, {0.2, 0.3});
  calibrate::FitRequest req;
  req.targets = {{"phi_peak", phi_peak_fn(31.3, 0.27)}, {"repose", 10.0 + 0.4 * 31.3 + 20.0 * 0.27}};
  std::vector<std::pair<int, std::vector<calibrate::RefinePoint>>> calls;
  std::vector<std::string> ran;
  std::ostringstream log;
  calibrate::RefineOptions ro;
  ro.rounds = 1;
  ro.tolerance = 0;
  ro.log = &log;
  ro.run_points = [&](db::Store& st, const std::string& job, int round, const std::vector<calibrate::RefinePoint>& pts) {
    calls.emplace_back(round, pts);
    ran.push_back(calibrate::refine_job_name(job, round));
    std::set<double> t, e;
    for (const auto& p : pts) t.insert(p.theta), e.insert(p.eta);
    if (job == "rep")
      store_fake_repose(st, calibrate::refine_job_name(job, round), {t.begin(), t.end()}, {e.begin(), e.end()});
    else
      store_fake_job(st, calibrate::refine_job_name(job, round), {t.begin(), t.end()}, {e.begin(), e.end()}, 1, 0.0, 1);
  };
  ro.resume_round = [&](db::Store&, const std::string& sub) { ran.push_back("resume " + sub); };
  calibrate::Calibration cal = calibrate::calibrate(s, req);
  ASSERT_TRUE(cal.result.ok);
  const auto rounds = calibrate::refine(s, req, cal, ro);
  EXPECT_EQ(ran, (std::vector<std::string>{"tri.refine1", "rep.refine2", "tri.refine2"})) << log.str();
  ASSERT_FALSE(calls.empty());
  // Round 1's own points, read back from rep.refine1's grid.
  std::set<std::pair<double, double>> pts;
  for (const auto& p : calls[0].second) pts.insert({p.theta, p.eta});
  EXPECT_EQ(pts, (std::set<std::pair<double, double>>{{30, 0.2}, {30, 0.3}, {35, 0.2}, {35, 0.3}}));
  ASSERT_EQ(rounds.size(), 2u);
  EXPECT_TRUE(rounds[0].resumed);
  EXPECT_EQ(rounds[0].round, 1);
  EXPECT_NE(log.str().find("round 1 stopped before job tri"), std::string::npos) << log.str();
}

TEST_F(RefineRounds, ARoundThatCannotBeResumedDoesNotBlockNewRounds) {
  store_unfinished_round(1);
  ro.resume_round = [](db::Store&, const std::string&) {
    throw jobs::JobError("--out", "cannot write into the output folder /x");
  };
  calibrate::Calibration cal = calibrate::calibrate(s, req);
  const auto rounds = calibrate::refine(s, req, cal, ro);
  ASSERT_EQ(rounds.size(), 1u);
  EXPECT_EQ(rounds[0].round, 2);
  EXPECT_FALSE(rounds[0].resumed);
  EXPECT_NE(log.str().find("round 1 of job coarse cannot be resumed"), std::string::npos) << log.str();
  // An interrupt is no such error: it ends the refinement.
  store_unfinished_round(3);
  ro.resume_round = [](db::Store&, const std::string&) { throw std::runtime_error("refinement interrupted"); };
  cal = calibrate::calibrate(s, req);
  EXPECT_THROW(calibrate::refine(s, req, cal, ro), std::runtime_error);
}

TEST(CalibrateRefine, DemRoundResumerRunsOnlyTheRoundsUnfinishedTasks) {
  TempDir d;
  db::Store s(d.file("demcal.db"));
  const nlohmann::json spec = small_collision_job("col.refine1", {{"theta_deg", {10, 20}}, {"eta", {0.1, 0.2}}});
  std::ostringstream log;
  // Recorded, as a run does before its first task, and then cut off with one task done.
  const jobs::Job job = jobs::parse_job(spec.dump(), "test");
  jobs::record_job(s, job, jobs::Shard{}, log);
  auto tasks = s.tasks("col.refine1");
  ASSERT_EQ(tasks.size(), 4u);
  ASSERT_TRUE(s.claim(tasks[0].id, "earlier"));
  db::Outcome o;
  o.status = "done";
  o.metrics = {{"marker", 42.0}};
  s.finish(tasks[0].id, "earlier", o);
  calibrate::dem_round_resumer(d.file("out"), 2, &log)(s, "col.refine1");
  tasks = s.tasks("col.refine1");
  for (const auto& t : tasks) EXPECT_EQ(t.status, "done") << log.str();
  // The task done before stays as it was: only the three others ran.
  const auto rows = jobs::select_rows(s, "col.refine1", {});
  int markers = 0;
  for (const auto& r : rows)
    markers += std::any_of(r.metrics.begin(), r.metrics.end(), [](const auto& m) { return m.first == "marker"; });
  EXPECT_EQ(markers, 1);
}

TEST(CalibrateRefine, DemRunnerAppendsASubJobThroughTheJobsRunner) {
  TempDir d;
  const std::string db = d.file("demcal.db");
  db::Store s(db);
  const nlohmann::json spec = small_collision_job("col", {{"theta_deg", {10, 20}}, {"eta", {0.1, 0.2}}});
  const jobs::Job job = jobs::parse_job(spec.dump(), "test");
  jobs::RunOptions ro;
  ro.workers = 2;
  ro.out_dir = d.file("out");
  std::ostringstream log;
  ro.log = &log;
  ASSERT_EQ(jobs::run_job(s, job, ro).done, 4);
  const auto runner = calibrate::dem_point_runner(d.file("out"), 2, &log);
  runner(s, "col", 1, {{15, 0.15}, {17.5, 0.15}, {15, 0.175}, {17.5, 0.175}});
  const auto sub = s.tasks(calibrate::refine_job_name("col", 1));
  ASSERT_EQ(sub.size(), 4u);
  for (const auto& t : sub) EXPECT_EQ(t.status, "done");
  const auto rs = calibrate::gather(s, "col", "dt");
  EXPECT_EQ(rs.points.size(), 8u);
  EXPECT_EQ(rs.with_data(), 8);
  EXPECT_EQ(calibrate::refine_jobs_of(s, "col"), std::vector<std::string>{"col.refine1"});
  EXPECT_EQ(calibrate::base_jobs(s), std::vector<std::string>{"col"});
}

// Runs a job spec into the store on two workers; the number of tasks done.
int run_spec(db::Store& s, const nlohmann::json& spec, const std::string& out, std::ostringstream& log) {
  jobs::RunOptions ro;
  ro.workers = 2;
  ro.out_dir = out;
  ro.log = &log;
  return jobs::run_job(s, jobs::parse_job(spec.dump(), "test"), ro).done;
}

TEST(CalibrateRefine, ARefinementRunsOnlyTheValueAPinnedAxisWasFittedAt) {
  // The fit read dt_factor = 0.1 only (--where): its refinement runs that value only,
  // not every value of the axis (which would double its cost here).
  TempDir d;
  db::Store s(d.file("demcal.db"));
  const nlohmann::json spec = small_collision_job("pin", {{"theta_deg", {10, 20}}, {"eta", {0.1, 0.2}}, {"dt_factor", {0.1, 0.2}}});
  std::ostringstream log;
  ASSERT_EQ(run_spec(s, spec, d.file("out"), log), 8);
  const auto runner = calibrate::dem_point_runner(d.file("out"), 2, &log, {jobs::parse_where("dt_factor=0.1")});
  runner(s, "pin", 1, {{15, 0.15}, {17.5, 0.175}});
  const auto sub = s.tasks(calibrate::refine_job_name("pin", 1));
  ASSERT_EQ(sub.size(), 4u);  // 2 theta x 2 eta, one dt_factor
  for (const auto& t : sub) EXPECT_EQ(nlohmann::json::parse(t.params_json)["dt_factor"].get<double>(), 0.1);
}

TEST(CalibrateRefine, ARefinementPinsAGradingCurveAxisWrittenWithIntegers) {
  // --where gives the curve as a user types it (spaces, 10.0 for 10); the stored grid
  // holds it as the job file wrote it, the task parameters as reals: both must match.
  TempDir d;
  db::Store s(d.file("demcal.db"));
  const nlohmann::json fine = {{"d", {0.0006, 0.001, 0.002}}, {"percent_finer", {0, 40, 100}}};
  const nlohmann::json coarse = {{"d", {0.0006, 0.001, 0.002}}, {"percent_finer", {0, 10, 100}}};
  nlohmann::json spec = small_collision_job("curves", {{"theta_deg", {10, 20}}, {"eta", {0.1, 0.2}}, {"grading", {fine, coarse}}});
  spec["material"].erase("diameter");
  std::ostringstream log;
  ASSERT_EQ(run_spec(s, spec, d.file("out"), log), 8);
  const auto runner = calibrate::dem_point_runner(d.file("out"), 2, &log, {jobs::parse_where(R"(grading={"d": [0.0006, 0.001, 0.002], "percent_finer": [0, 10.0, 100]})")});
  runner(s, "curves", 1, {{15, 0.15}, {17.5, 0.175}});
  const auto sub = s.tasks(calibrate::refine_job_name("curves", 1));
  ASSERT_EQ(sub.size(), 4u);  // 2 theta x 2 eta, one curve
  for (const auto& t : sub)
    EXPECT_EQ(nlohmann::json::parse(t.params_json)["grading"]["percent_finer"][1].get<double>(), 10.0) << t.params_json;
}

}  // namespace
}  // namespace demcal::test
