// cnc-fleet: the fleet page. A reader of a broker the cells' cnc-mqtt publish to
// (docs/mqtt.md): it subscribes to PREFIX/+/status, state, job/end and job/last and
// serves a page (services/mqtt/www) that lists the cells, their state and last jobs,
// and the same as JSON (/fleet.json). It publishes nothing and reaches no cell.
//
//   cnc-fleet [--broker HOST] [--broker-port P] [--prefix cnc] [--user U --password-file F]
//             [--ca-file CA] [--listen 127.0.0.1] [--port 8090]
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <chrono>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>

#include "common/service/service.h"
#include "common/util/install.h"
#include "common/util/signals.h"
#include "services/mqtt/fleet_view.h"
#include "services/mqtt/mqtt_client.h"

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
using tcp = asio::ip::tcp;

namespace {

bool read_whole(const std::string& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream s;
  s << in.rdbuf();
  *out = s.str();
  return true;
}

http::response<http::string_body> answer(const http::request<http::string_body>& req, http::status st,
                                         std::string body, const char* type) {
  http::response<http::string_body> res{st, req.version()};
  res.set(http::field::server, "cnc-fleet");
  res.set(http::field::content_type, type);
  res.set(http::field::cache_control, "no-store");
  res.set("X-Content-Type-Options", "nosniff");
  res.set("Content-Security-Policy", "default-src 'self'; connect-src 'self'; style-src 'self'; frame-ancestors 'none'");
  res.keep_alive(false);
  res.body() = std::move(body);
  res.prepare_payload();
  return res;
}

int run_fleet(const cnc::config::MachineConfig&, const cnc::service::Args& args) {
  const std::string password_file = args.option("password-file");
  cnc::mqtt::ClientOptions o;
  o.host = args.option("broker", "127.0.0.1");
  o.ca_file = args.option("ca-file");
  o.port = static_cast<int>(args.number("broker-port", o.ca_file.empty() ? 1883 : 8883));
  o.username = args.option("user");
  if (!password_file.empty()) {
    std::ifstream in(password_file);
    if (!in || !std::getline(in, o.password) || o.password.empty())
      throw cnc::service::FlagError("--password-file: " + password_file + " has no password on its first line");
  }
  const std::string prefix = args.option("prefix", "cnc");
  o.client_id = "cnc-fleet-" + std::to_string(::getpid());
  o.clean_session = true;  // a page shows what is retained and what comes while it runs
  o.subscribe = {prefix + "/+/status", prefix + "/+/state", prefix + "/+/job/end", prefix + "/+/job/last"};
  cnc::mqtt::FleetView view(prefix);
  std::mutex mu;
  o.on_message = [&](const std::string& topic, const std::string& payload) {
    std::lock_guard<std::mutex> lock(mu);
    view.on_message(topic, payload);
  };
  const int port = static_cast<int>(args.number("port", 8090));
  if (port < 1 || port > 65535) throw cnc::service::FlagError("--port: " + args.option("port") + " is not a TCP port");
  asio::io_context ioc;
  tcp::acceptor acceptor(ioc, {asio::ip::make_address(args.option("listen", "127.0.0.1")), static_cast<unsigned short>(port)});
  acceptor.non_blocking(true);
  cnc::mqtt::MqttClient client(o);
  client.start();
  const std::string www = cnc::util::resource_path("services/mqtt/www");
  spdlog::info("cnc-fleet: the fleet page on http://{}:{}/ ({}/+/... from {}:{})", args.option("listen", "127.0.0.1"),
               port, prefix, o.host, o.port);
  while (!cnc::util::stop_requested()) {
    beast::error_code ec;
    tcp::socket socket(ioc);
    acceptor.accept(socket, ec);
    if (ec == asio::error::would_block || ec == asio::error::try_again) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      continue;
    }
    if (ec) continue;
    socket.non_blocking(false);
    beast::flat_buffer buffer;
    http::request<http::string_body> req;
    http::read(socket, buffer, req, ec);
    if (ec) continue;
    std::string target(req.target());
    if (const size_t q = target.find('?'); q != std::string::npos) target.resize(q);
    http::response<http::string_body> res;
    std::string body;
    if (req.method() != http::verb::get) {
      res = answer(req, http::status::method_not_allowed, "cnc-fleet: GET only\n", "text/plain; charset=utf-8");
    } else if (target == "/fleet.json") {
      std::lock_guard<std::mutex> lock(mu);
      nlohmann::json j = view.to_json();
      j["broker"] = {{"host", o.host}, {"port", o.port}, {"connected", client.connected()}};
      res = answer(req, http::status::ok, j.dump(), "application/json");
    } else if ((target == "/" || target == "/fleet.html") && read_whole(www + "/fleet.html", &body)) {
      res = answer(req, http::status::ok, std::move(body), "text/html; charset=utf-8");
    } else if (target == "/fleet.js" && read_whole(www + "/fleet.js", &body)) {
      res = answer(req, http::status::ok, std::move(body), "text/javascript; charset=utf-8");
    } else if (target == "/fleet.css" && read_whole(www + "/fleet.css", &body)) {
      res = answer(req, http::status::ok, std::move(body), "text/css; charset=utf-8");
    } else {
      res = answer(req, http::status::not_found, "cnc-fleet: no " + target + "\n", "text/plain; charset=utf-8");
    }
    http::write(socket, res, ec);
    socket.shutdown(tcp::socket::shutdown_send, ec);
  }
  client.stop({}, 0.0);
  return cnc::service::kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  cnc::service::Spec spec{
      "cnc-fleet",
      "the fleet page: the cells a broker knows (their cnc-mqtt records), their state and last jobs",
      {{"broker", "HOST", "the broker (default 127.0.0.1)"},
       {"broker-port", "P", "its port (default 1883; 8883 with --ca-file)", true},
       {"prefix", "PREFIX", "the cells' mqtt.topic_prefix (default cnc)"},
       {"user", "USER", "the broker user that reads the cells (the ACL's fleet reader)"},
       {"password-file", "FILE", "its password, on the first line"},
       {"ca-file", "FILE", "TLS: the CA that signed the broker's certificate"},
       {"listen", "ADDRESS", "where the page is served (default 127.0.0.1)"},
       {"port", "P", "its port (default 8090)", true}},
      {}};
  spec.needs_machine = false;
  return cnc::service::run(spec, argc, argv, run_fleet);
}
