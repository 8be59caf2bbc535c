// cnc-key: the cell's signing keys (common/bus/auth.h).
//
//   cnc-key gen    (--machine FILE | --file KEYFILE) [--if-missing] [--force]
//   cnc-key rotate (--machine FILE | --file KEYFILE) [--grace S] [--activate-in S]
//   cnc-key show   (--machine FILE | --file KEYFILE)
//
// gen writes one new key (mode 0600). rotate adds a new key that every running
// service accepts as soon as it has read the changed file (each checks it once a
// second) but that signs only --activate-in seconds later (3 by default: every
// service on this PC knows it by then; for a cell over several PCs, give the time to
// copy the file to all of them); the keys before it stay accepted for --grace
// seconds after that (60 by default), for messages in flight and PCs still behind. show prints the
// key ids and their times, never a secret. Exit 0 done, 1 failed, 2 bad arguments
// or an unusable key file.
#include <sys/stat.h>

#include <cstdio>
#include <ctime>
#include <filesystem>
#include <string>

#include "common/bus/auth.h"
#include "common/config/machine_config.h"
#include "common/config/yaml_reader.h"
#include "common/util/cli.h"
#include "common/util/clock.h"

namespace {
std::string when(int64_t utime) {
  if (utime == 0) return "-";
  const std::time_t t = static_cast<std::time_t>(utime / 1'000'000);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[40];
  std::strftime(b, sizeof b, "%Y-%m-%d %H:%M:%S UTC", &tm);
  return b;
}

void show(const std::string& path, const cnc::bus::KeySet& ks) {
  const int64_t now = cnc::util::wall_utime();
  const cnc::bus::Key* signer = ks.signing_key(now);
  std::printf("key file %s: %d key(s)\n", path.c_str(), ks.count);
  for (int i = 0; i < ks.count; ++i) {
    const cnc::bus::Key& k = ks.keys[static_cast<size_t>(i)];
    const char* state = &k == signer ? "signing"
                        : (k.accept_until_utime != 0 && k.accept_until_utime < now) ? "expired"
                        : k.sign_from_utime > now                                     ? "accepted, signs later"
                                                                                      : "accepted (grace)";
    std::printf("  key %08x  signs from %s  accepted until %s  [%s]\n", k.id, when(k.sign_from_utime).c_str(),
                when(k.accept_until_utime).c_str(), state);
  }
}
}  // namespace

int main(int argc, char** argv) {
  std::string machine, file;
  bool if_missing = false, force = false;
  double grace_s = 60.0, activate_s = 3.0;
  CLI::App app{"the cell's signing keys: gen, rotate, show", "cnc-key"};
  cnc::util::cli::setup(app);
  app.require_subcommand(1, 1);
  const auto key_file = [&](CLI::App* c) {
    auto* m = c->add_option("--machine", machine, "the cell's machine config: its security.key_file")->type_name("FILE");
    auto* f = c->add_option("--file", file, "the key file")->type_name("KEYFILE");
    m->excludes(f);
    f->excludes(m);
    return c;
  };
  CLI::App* gen = key_file(app.add_subcommand("gen", "write one new key (mode 0600)"));
  gen->add_flag("--if-missing", if_missing, "do nothing when the key file exists");
  gen->add_flag("--force", force, "replace an existing key file");
  CLI::App* rotate = key_file(app.add_subcommand("rotate", "add a new key; the ones before it stay accepted a while"));
  rotate->add_option("--grace", grace_s, "seconds the keys before the new one stay accepted after it signs")
      ->type_name("S")->check(cnc::util::cli::non_negative());
  rotate->add_option("--activate-in", activate_s, "seconds until the new key signs (every PC must know it by then)")
      ->type_name("S")->check(cnc::util::cli::non_negative());
  key_file(app.add_subcommand("show", "the key ids and their times, never a secret"));
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  const std::string cmd = app.get_subcommands().front()->get_name();
  if (machine.empty() == file.empty()) return cnc::util::cli::bad_flag(app, cmd + ": --machine FILE or --file KEYFILE is required");
  try {
    if (!machine.empty()) {
      const auto cfg = cnc::config::load_machine_config(machine);
      if (cfg.security.key_file.empty()) {
        std::fprintf(stderr, "cnc-key: %s has no security.key_file\n", machine.c_str());
        return 2;
      }
      file = cfg.security.key_file;
    }
    if (cmd == "gen") {
      if (std::filesystem::exists(file)) {
        if (if_missing) return 0;
        if (!force) {
          std::fprintf(stderr, "cnc-key: %s exists; not overwritten (--force replaces it, or: cnc-key rotate)\n",
                       file.c_str());
          return 1;
        }
      }
      const auto dir = std::filesystem::path(file).parent_path();
      if (!dir.empty() && !std::filesystem::exists(dir)) {
        std::filesystem::create_directories(dir);
        std::filesystem::permissions(dir, std::filesystem::perms::owner_all);
      }
      cnc::bus::KeySet ks;
      ks.add(cnc::bus::generate_key());
      cnc::bus::write_key_file(file, ks);
      std::printf("cnc-key: new key %08x in %s (mode 0600)\n", ks.keys[0].id, file.c_str());
      return 0;
    }
    if (cmd == "rotate") {
      const cnc::bus::KeySet old = cnc::bus::read_key_file(file);
      const cnc::bus::KeySet ks = cnc::bus::rotate_keys(old, cnc::util::wall_utime(), activate_s, grace_s);
      cnc::bus::write_key_file(file, ks);
      std::printf("cnc-key: rotated: new key %08x signs in %g s; the keys before it are accepted %g s longer\n",
                  ks.keys[static_cast<size_t>(ks.count - 1)].id, activate_s, grace_s);
      show(file, ks);
      return 0;
    }
    show(file, cnc::bus::read_key_file(file));
    return 0;
  } catch (const cnc::config::ConfigError& e) {
    std::fprintf(stderr, "cnc-key: config error: %s\n", e.what());
    return 2;
  } catch (const cnc::bus::KeyFileError& e) {
    std::fprintf(stderr, "cnc-key: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cnc-key: %s\n", e.what());
    return 1;
  }
}
