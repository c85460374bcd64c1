#include "server/commands.h"

#include <filesystem>
#include <iostream>
#include <memory>

#include "engine/util/check.h"
#include "server/cli/args.h"
#include "storage/data_dir.h"
#include "storage/postgres_job_store.h"
#include "storage/sqlite_job_store.h"
#include "storage/store_copy.h"

namespace omnirig::server {
namespace {

// "sqlite:DIR" (the SQLite database of data folder DIR) or a postgresql:// URL.
std::unique_ptr<storage::JobStore> OpenStore(const std::string& name, const std::string& option,
                                             bool must_exist) {
  if (storage::IsPostgresUrl(name)) return std::make_unique<storage::PostgresJobStore>(name);
  const std::string prefix = "sqlite:";
  if (name.rfind(prefix, 0) != 0 || name.size() == prefix.size()) {
    throw InvalidArgument("--" + option + " must be sqlite:DIR (a data folder) or a " +
                          "postgresql:// URL, got '" + name + "'");
  }
  const std::filesystem::path root = name.substr(prefix.size());
  if (must_exist && !std::filesystem::exists(root / "omnirig.db")) {
    throw InvalidArgument("--" + option + ": no omnirig database in " + root.string());
  }
  const storage::DataDir data_dir(root);
  return std::make_unique<storage::SqliteJobStore>(data_dir.DatabasePath().string());
}

}  // namespace

int StoreCommand(const std::vector<std::string>& args) {
  if (args.empty() || args[0] != "copy") {
    std::cerr << "usage: omnirig store copy --from sqlite:DIR --to postgresql://USER@HOST:PORT/DB"
              << std::endl;
    return args.size() == 1 && (args[0] == "--help" || args[0] == "-h") ? 0 : 2;
  }
  cli::ArgParser parser("store copy",
                        "Copies every record (datasets, images, jobs, results, artifact records) "
                        "from one job store to another, keeping ids, states and times. Files stay "
                        "in the data folder: move or mount it as --data of the new service. "
                        "Records already in the destination are skipped.");
  parser.AddOption("from", "", "source: sqlite:DIR (a data folder) or postgresql://...");
  parser.AddOption("to", "", "destination: postgresql://USER@HOST:PORT/DB or sqlite:DIR");
  if (!parser.Parse(std::vector<std::string>(args.begin() + 1, args.end()))) {
    return parser.exit_code();
  }
  OMNIRIG_CHECK(!parser.Get("from").empty() && !parser.Get("to").empty(),
                "both --from and --to are required");
  OMNIRIG_CHECK(parser.Get("from") != parser.Get("to"), "--from and --to name the same store");
  auto from = OpenStore(parser.Get("from"), "from", /*must_exist=*/true);
  auto to = OpenStore(parser.Get("to"), "to", /*must_exist=*/false);
  const storage::StoreCopyReport report = storage::CopyStore(*from, *to);
  std::cout << "copied " << report.datasets << " dataset(s) with " << report.images
            << " image record(s), " << report.jobs << " job(s) with " << report.artifacts
            << " artifact record(s); skipped " << report.datasets_skipped << " dataset(s) and "
            << report.jobs_skipped << " job(s) already there" << std::endl;
  return 0;
}

}  // namespace omnirig::server
