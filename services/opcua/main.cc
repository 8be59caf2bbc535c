// cnc-opcua: the cell as an OPC UA server (OPC 40501-1 Machine Tools), a client of
// the cell through the HMI's API like a browser. The server is node-opcua's
// (services/opcua/*.js, run by node); this program is its front door: it reads the
// machine config with the cell's own strict reader (a bad key exits 2 naming its
// path, as every service does), checks the HMI password file, and hands node the
// resolved settings. docs/opcua.md has the address space and the mapping.
//
//   cnc-opcua --machine M [--state DIR] [--port P]
//   cnc-opcua --machine M --print-url        the endpoint's address (exit 3: no opcua: section)
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/service/service.h"
#include "common/util/install.h"

namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

constexpr int kExitNotConfigured = 3;

// "" when `path` is a regular file of this user that group and others cannot access.
std::string password_file_problem(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    return "opcua.hmi_password_file " + path + ": " + std::strerror(errno);
  if (!S_ISREG(st.st_mode)) return "opcua.hmi_password_file " + path + " is not a regular file";
  if (st.st_uid != ::geteuid() && ::geteuid() != 0)
    return "opcua.hmi_password_file " + path + " belongs to uid " + std::to_string(st.st_uid) +
           ", not to this user (uid " + std::to_string(::geteuid()) + ")";
  if ((st.st_mode & 077) != 0) {
    char mode[8];
    std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
    return "opcua.hmi_password_file " + path + " has mode " + mode +
           ": group or others may access it; it must be readable by its owner only (chmod 600 " + path + ")";
  }
  return "";
}

// Where the HMI is reached from this PC: its listen address, a wildcard one by loopback.
std::string hmi_url(const cnc::config::HmiConfig& h) {
  std::string host = h.listen;
  if (host == "0.0.0.0" || host == "localhost") host = "127.0.0.1";
  if (host == "::") host = "::1";
  if (host.find(':') != std::string::npos) host = "[" + host + "]";
  return "http://" + host + ":" + std::to_string(h.port);
}

// node_modules (npm ci from package-lock.json): beside the scripts when installed
// (/usr/share/cnc/services/opcua), in the build tree beside this program otherwise.
std::string node_modules_dir() {
  const std::string installed = cnc::util::resource_path("services/opcua/node_modules");
  std::error_code ec;
  if (fs::is_directory(installed, ec)) return installed;
  return cnc::util::executable_dir() + "/opcua/node_modules";
}

int run_opcua(const cnc::config::MachineConfig& cfg, const cnc::service::Args& args) {
  const cnc::config::OpcuaConfig& o = cfg.opcua;
  if (!o.enabled) {
    std::fprintf(stderr, "cnc-opcua: %s has no opcua: section: nothing to serve (docs/opcua.md)\n",
                 args.machine_file.c_str());
    return kExitNotConfigured;
  }
  const int port = static_cast<int>(args.number("port", o.port));
  if (port < 1 || port > 65535) throw cnc::service::FlagError("--port: " + args.option("port") + " is not a TCP port");
  std::string host = o.listen.find(':') != std::string::npos ? "[" + o.listen + "]" : o.listen;
  const std::string url = "opc.tcp://" + host + ":" + std::to_string(port);
  if (args.flags.count("print-url")) {
    std::printf("%s\n", url.c_str());
    return 0;
  }
  if (!o.hmi_password_file.empty()) {
    if (const std::string why = password_file_problem(o.hmi_password_file); !why.empty()) {
      std::fprintf(stderr, "cnc-opcua: config error: %s\n", why.c_str());
      return cnc::service::kExitBadInput;
    }
  }
  const std::string script = cnc::util::resource_path("services/opcua/server.js");
  const std::string modules = node_modules_dir();
  std::error_code ec;
  if (!fs::is_directory(modules + "/node-opcua", ec)) {
    std::fprintf(stderr, "cnc-opcua: %s/node-opcua is missing: build the tree (./cnc build runs npm ci)\n",
                 modules.c_str());
    return cnc::service::kExitFailure;
  }
  // The state (the server's certificate and key, its counters) beside the machine
  // file unless --state names a folder: ./cnc up's CNC_STATE_DIR, /var/lib/cnc installed.
  const fs::path state_root = args.option("state", fs::path(args.machine_file).parent_path().string());
  const fs::path state = state_root / (fs::path(args.machine_file).stem().string() + ".opcua");

  json settings = {
      {"cell", cfg.name},
      {"version", cnc::util::version()},
      {"machine_file", args.machine_file},
      {"state_dir", fs::absolute(state).lexically_normal().string()},
      {"endpoint_url", url},
      {"listen", o.listen},
      {"port", port},
      {"anonymous", o.anonymous},
      {"allow_security_none", o.allow_security_none},
      {"trust_unknown_clients", o.trust_unknown_clients},
      {"hmi",
       {{"url", hmi_url(cfg.hmi)},
        {"login", !cfg.hmi.users_file.empty()},
        {"view_without_login", cfg.hmi.read_only_without_login},
        {"user", o.hmi_user},
        {"password_file", o.hmi_password_file}}},
      {"identification",
       {{"manufacturer", o.manufacturer},
        {"model", o.model},
        {"serial_number", o.serial_number},
        {"product_instance_uri", o.product_instance_uri},
        {"year_of_construction", o.year_of_construction}}},
      {"spindle", cfg.spindle.enabled},
  };
  // node finds node-opcua by NODE_PATH (the scripts and their modules need not share a
  // folder); everything it writes (the private key above all) is the user's only.
  ::setenv("NODE_PATH", modules.c_str(), 1);
  ::setenv("CNC_OPCUA_SETTINGS", settings.dump().c_str(), 1);
  ::umask(077);
  std::fflush(stdout);
  const char* node = std::getenv("CNC_NODE");
  if (node == nullptr || *node == '\0') node = "node";
  std::vector<char*> argv = {const_cast<char*>(node), const_cast<char*>(script.c_str()), nullptr};
  ::execvp(node, argv.data());
  std::fprintf(stderr, "cnc-opcua: cannot run %s: %s (Debian's nodejs package: ./cnc installs it)\n", node,
               std::strerror(errno));
  return cnc::service::kExitFailure;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{
      "cnc-opcua",
      "the cell as an OPC UA server (OPC 40501-1 Machine Tools), a client of the cell through the HMI's API",
      {{"state", "DIR", "where the server keeps its certificate and counters (default: the config's folder)"},
       {"port", "P", "the opc.tcp port (default: the config's opcua.port)", true}},
      {{"print-url", "", "print the endpoint's address from the config and exit (3: the config has no opcua: section)"}}};
  return cnc::service::run(spec, argc, argv, run_opcua);
}
