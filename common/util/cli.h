#pragma once
// Every program's command line in one style (CLI11): --help (-h) prints the summary
// and each option with its description, --version prints "NAME VERSION", and an
// unknown or malformed flag exits 2 with "NAME: what, naming the flag (see NAME --help)".
//
//   CLI::App app{"the cell's signing keys", "cnc-key"};
//   cnc::util::cli::setup(app);
//   app.add_option("--file", file, "the key file")->type_name("KEYFILE");
//   if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
#include <CLI/CLI.hpp>
#include <string>

namespace cnc::util::cli {

inline constexpr int kExitBadFlag = 2;

// Gives `app` (made as CLI::App{summary, name}) the style: --help starting with
// "NAME: summary", -h/--help and --version described, defaults shown.
void setup(CLI::App& app);

// Parses argv: -1 when the program goes on; otherwise the exit code to return at
// once (0 after --help or --version, kExitBadFlag after an error, printed on stderr).
int parse(CLI::App& app, int argc, char** argv);

// Number checks with a plain message ("--grace: -1 is negative"), in place of
// CLI11's PositiveNumber/NonNegativeNumber (which print the double range).
CLI::Validator positive();
CLI::Validator non_negative();

// The same error as parse() gives, for a check made after parsing (e.g. two options
// that exclude each other): prints "NAME: what (see NAME --help)", returns kExitBadFlag.
int bad_flag(const CLI::App& app, const std::string& what);

}  // namespace cnc::util::cli
