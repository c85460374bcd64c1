#pragma once
// `omnirig store copy --from sqlite:DIR --to postgresql://...`: moves a one-machine service's
// records (datasets, jobs, results, artifact records) into a shared PostgreSQL store (or back),
// so a team keeps its history when it grows to several machines.

#include <string>
#include <vector>

namespace omnirig::server {

int StoreCommand(const std::vector<std::string>& args);

}  // namespace omnirig::server
