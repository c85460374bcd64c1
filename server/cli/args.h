#pragma once
// A small command-line parser shared by every `omnirig` subcommand: `--name VALUE` options,
// `--flag` switches, positional arguments, and `--help` generated from the declarations.

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace omnirig::cli {

class ArgParser {
 public:
  ArgParser(std::string command, std::string summary);

  // An option taking a value; `default_value` is shown in --help and returned when absent.
  void AddOption(const std::string& name, const std::string& default_value,
                 const std::string& help);
  void AddFlag(const std::string& name, const std::string& help);
  // Describes the positional arguments in --help (e.g. "IMAGES...").
  void SetPositional(const std::string& name, const std::string& help);

  // Returns false when the command should exit: after printing --help (exit code 0, see
  // exit_code()) or an error (exit code 2).
  bool Parse(const std::vector<std::string>& args);
  int exit_code() const { return exit_code_; }

  std::string Get(const std::string& name) const;
  double GetDouble(const std::string& name) const;  // throws InvalidArgument on bad numbers
  int GetInt(const std::string& name) const;
  bool Has(const std::string& name) const;  // flag given, or option given explicitly
  const std::vector<std::string>& positional() const { return positional_; }
  std::string Help() const;

 private:
  struct Option {
    std::string default_value;
    std::string help;
    bool is_flag = false;
  };
  std::string command_, summary_, positional_name_, positional_help_;
  std::vector<std::string> order_;
  std::map<std::string, Option> options_;
  std::map<std::string, std::string> values_;
  std::vector<std::string> positional_;
  int exit_code_ = 0;
};

}  // namespace omnirig::cli
