#pragma once
// The store's schema: its version lives in PRAGMA user_version, its owner in
// PRAGMA application_id. Migrations take version v to v+1, one transaction each.
#include "sqlite.hpp"

#include <string>

namespace demcal::db {

constexpr int kSchemaVersion = 2;
constexpr int kApplicationId = 0x64656d63;  // "demc"

// Inspects an existing file read-only and throws DbError(bad_input) when it is not
// a demcal database we can use: not SQLite, corrupt, someone else's, or newer.
// A missing or empty file passes (it will be created).
void check_file(const std::string& path);

// Brings a read-write connection from its version to kSchemaVersion.
void migrate(Connection& c);

}  // namespace demcal::db
