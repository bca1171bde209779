#pragma once
// What every scene's resolve() shares: the time-step pair, the diameter range and
// the engine's own validation turned into a job-file error.
#include "engine/errors.hpp"
#include "engine/size_distribution.hpp"

#include <nlohmann/json.hpp>
#include <ostream>
#include <sstream>
#include <string>

namespace demcal::jobs {

// dt and dt_factor exclude each other ("<section>.dt"); with neither, dt_factor
// takes `default_factor`.
void resolve_time_step(nlohmann::json& params, const std::string& section, double default_factor);

// material.diameter: min and max default to the engine's (or to a grading curve's
// first and last size) and min must not exceed max; a distribution named "uniform" is
// the default and is dropped, so that a job that writes it out keeps the keys (and
// the --where matches) of one that leaves it out; a curve must make a grading.
void resolve_diameters(nlohmann::json& params);

// Starts the next of a scene's advice notes in `os` (they are joined with "; "),
// written at the significant digits it needs.
std::ostream& next_note(std::ostringstream& os, int precision);

// A note when min and max cut a grading curve to less than 80% of its mass: the
// sample is the curve's middle, not the sand (its share of fines and of coarse grains
// is gone); "" otherwise.
std::string grading_cut_note(const engine::Grading& g);

// Drops `key` when it holds `value` (numbers compared by value, 0 == 0.0): a default
// written out keeps the task key, and the --where matches, of a job that leaves it out.
void erase_default(nlohmann::json& params, const std::string& key, const nlohmann::json& value);

// Rethrows the engine's ConfigError as a JobError at `job_path` (the job-file
// spelling of e.field()), keeping only the reason.
[[noreturn]] void throw_as_job_error(const engine::ConfigError& e, const std::string& job_path);

}  // namespace demcal::jobs
