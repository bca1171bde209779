#pragma once
// Grid expansion: the Cartesian product of the axes, times replicas (seed + r).
#include "validate.hpp"

#include <cstdint>
#include <nlohmann/json.hpp>
#include <vector>

namespace demcal::jobs {

// Number of tasks the product gives, saturating instead of overflowing.
std::uint64_t grid_size(const ParamSet& set, int replicas);

// Flat parameters of every task; the last axis varies fastest, replicas innermost.
std::vector<nlohmann::json> expand(const ParamSet& set, int replicas, std::uint64_t seed);

}  // namespace demcal::jobs
