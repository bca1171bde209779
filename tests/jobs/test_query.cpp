// query's metric columns: the names a user types, read against what tasks store.
#include "jobs/decimal.hpp"
#include "jobs/job_error.hpp"
#include "jobs/query.hpp"

#include <gtest/gtest.h>

#include <sstream>

using demcal::jobs::Format;
using demcal::jobs::JobError;
using demcal::jobs::ResultRow;

namespace {
ResultRow triaxial_row(double peak, double cv) {
  ResultRow r;
  r.task.id = 1;
  r.task.status = "done";
  r.task.scene = "triaxial";
  r.params = {{"theta_deg", 30.0}};
  r.metrics = {{"phi_peak_deg", peak}, {"phi_cv_deg", cv}, {"wall_s", 1.0}};
  return r;
}
}  // namespace

// map and fit take phi_peak, phi_cv, repose; query reads them as the stored angles.
TEST(Query, TheNamesMapAndFitTakeReadTheStoredAngles) {
  const std::vector<ResultRow> rows = {triaxial_row(40.25, 27.5)};
  std::ostringstream by_alias, by_name;
  demcal::jobs::print_rows(by_alias, rows, {"phi_peak", "phi_cv"}, Format::csv);
  demcal::jobs::print_rows(by_name, rows, {"phi_peak_deg", "phi_cv_deg"}, Format::csv);
  EXPECT_EQ(by_alias.str(), by_name.str());
  EXPECT_NE(by_alias.str().find("phi_peak_deg,phi_cv_deg"), std::string::npos) << by_alias.str();
  EXPECT_NE(by_alias.str().find("40.25"), std::string::npos) << by_alias.str();
  std::ostringstream both;  // asked twice, shown once
  demcal::jobs::print_rows(both, rows, {"phi_peak", "phi_peak_deg", "phi_cv"}, Format::csv);
  EXPECT_EQ(both.str(), by_name.str());
  // A name neither stored nor an angle's is still a typo.
  std::ostringstream sink;
  try {
    demcal::jobs::print_rows(sink, rows, {"phi_peek"}, Format::csv);
    FAIL() << "phi_peek accepted";
  } catch (const JobError& e) {
    EXPECT_NE(std::string(e.what()).find("no task stores a metric \"phi_peek\""), std::string::npos) << e.what();
  }
}

// --where values are read as a user types numbers: " 30" matched where "30 " did not
// (strtod skips leading spaces only), and "0x1e" matched 30 (strtod reads hex).
TEST(Query, AWhereNumberIsDecimalWithNothingAround) {
  using demcal::jobs::value_matches;
  const nlohmann::json thirty = 30.0;
  for (const char* yes : {"30", "30.0", "3e1", "+30"}) EXPECT_TRUE(value_matches(thirty, yes)) << yes;
  for (const char* no : {" 30", "30 ", "0x1e", "0X1E", "30abc", ""}) EXPECT_FALSE(value_matches(thirty, no)) << no;
  double d = 0;
  EXPECT_TRUE(demcal::jobs::parse_decimal("-1.5e-3", d));
  EXPECT_EQ(d, -1.5e-3);
  EXPECT_TRUE(demcal::jobs::parse_decimal("inf", d));
  EXPECT_FALSE(demcal::jobs::parse_decimal("0x10", d));
}
