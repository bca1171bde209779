#pragma once
// The "material" section, shared by every scene. Degrees at the edge, radians inside.
#include "params.hpp"

#include "engine/material.hpp"

#include <nlohmann/json.hpp>
#include <vector>

namespace demcal::jobs {

std::vector<ParamSpec> material_params();
// From resolved flat parameters (kn, ks, density, b, theta_deg, eta, d_min, d_max, and
// size_distribution and grading when a job names a grading other than the default).
engine::Material material_from(const nlohmann::json& params);
// Engine field names ("material.friction_angle") back to job-file paths ("material.theta_deg").
std::string job_path_of(const std::string& engine_field, const std::string& scene_section);

}  // namespace demcal::jobs
