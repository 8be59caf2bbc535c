// cnc-netem: a loss-and-delay forwarder for a cell's UDP multicast (this kernel has
// no netem qdisc). It receives the datagrams of one multicast group and port on one
// side and sends them again, to the same group and port, on the other, dropping a
// random share and holding the rest for a random time (impairment.h: loss, delay ±
// jitter, seeded, order kept or not).
//
//   cnc-netem --group ADDR:PORT --from SIDE --to SIDE [--both]
//             [--loss PCT] [--delay MS] [--jitter MS] [--keep-order] [--seed N]
//             [--queue N] [--slot-bytes N] [--ttl N] [--realtime-priority N]
//
// A SIDE is a network namespace, NETNS[,IFNAME]: a namespace file (/proc/PID/ns/net,
// /run/netns/NAME) or "." for the forwarder's own, and optionally the interface to
// join the group and send on (default: the namespace's route for the group). The
// usual set-up in tests: two namespaces with nothing between them but this
// forwarder, each with multicast on its loopback (`ip route add 224.0.0.0/4 dev lo`),
// the cell's services split between them. --both forwards the other way too (the
// same parameters, the seed + 1). Datagrams the forwarder itself sent are never taken
// up again (their source port is one of its own in that namespace).
//
// One thread: ppoll on the receiving sockets until the next release is due; no
// allocation per datagram (the queue's slots are allocated at start). It stands for
// the network, so it runs at SCHED_FIFO 50 (--realtime-priority, 0 = normal), above
// the cell's cyclic services (40, 41): at normal priority, on this 2-core VM with a
// cell running, it held datagrams up to 156 ms (set: 2 ± 1 ms) and the bridge's
// watchdog tripped; at 50, 9 ms at most. Where that is not permitted it warns and
// runs at normal priority. At SIGTERM or
// SIGINT it prints its counters per direction to stderr and exits 0; what is still
// held is not sent (counted as left in queue). Exit 2 on bad arguments, 1 when a
// socket or namespace cannot be set up.
#include <arpa/inet.h>
#include <fcntl.h>
#include <net/if.h>
#include <netinet/in.h>
#include <poll.h>
#include <sched.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "common/util/cli.h"
#include "common/util/signals.h"
#include "tools/netem/impairment.h"

namespace {

using cnc::netem::Counters;
using cnc::netem::DelayQueue;
using cnc::netem::Impairment;
using cnc::netem::Params;

int bad(const std::string& why) {
  std::fprintf(stderr, "cnc-netem: %s (see cnc-netem --help)\n", why.c_str());
  return 2;
}

int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

bool parse_u64(const std::string& s, uint64_t* out) {
  if (s.empty() || s[0] == '-') return false;
  char* end = nullptr;
  errno = 0;
  *out = std::strtoull(s.c_str(), &end, 10);
  return errno == 0 && end != s.c_str() && *end == '\0';
}

struct Side {
  std::string netns;  // "." = own
  std::string ifname;
  dev_t dev = 0;
  ino_t ino = 0;
};

bool parse_side(const std::string& flag, const std::string& v, Side* s, std::string* err) {
  const auto comma = v.find(',');
  s->netns = v.substr(0, comma);
  s->ifname = comma == std::string::npos ? "" : v.substr(comma + 1);
  if (s->netns.empty()) {
    *err = flag + " '" + v + "': no namespace (use . for this process's own)";
    return false;
  }
  const std::string path = s->netns == "." ? "/proc/self/ns/net" : s->netns;
  struct stat st{};
  if (stat(path.c_str(), &st) != 0) {
    *err = flag + " '" + v + "': " + path + ": " + std::strerror(errno);
    return false;
  }
  s->dev = st.st_dev;
  s->ino = st.st_ino;
  return true;
}

// Runs the socket set-up of one side inside its namespace and comes back.
class NetnsGuard {
 public:
  NetnsGuard(int home_fd, const Side& side, std::string* err) : home_(home_fd) {
    if (side.netns == ".") return;
    const int fd = open(side.netns.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0 || setns(fd, CLONE_NEWNET) != 0) {
      *err = "cannot enter the network namespace " + side.netns + ": " + std::strerror(errno);
      if (fd >= 0) close(fd);
      return;
    }
    close(fd);
    entered_ = true;
  }
  ~NetnsGuard() {
    if (entered_ && setns(home_, CLONE_NEWNET) != 0) {
      std::fprintf(stderr, "cnc-netem: cannot return to its own network namespace: %s\n", std::strerror(errno));
      std::exit(1);
    }
  }
  NetnsGuard(const NetnsGuard&) = delete;
  NetnsGuard& operator=(const NetnsGuard&) = delete;

 private:
  int home_;
  bool entered_ = false;
};

int interface_index(const Side& side, std::string* err) {
  if (side.ifname.empty()) return 0;
  const unsigned idx = if_nametoindex(side.ifname.c_str());
  if (idx == 0) *err = "no interface '" + side.ifname + "' in " + side.netns + ": " + std::strerror(errno);
  return static_cast<int>(idx);
}

// The receiving socket: bound to the group and port, joined on the side's interface,
// only this socket's memberships (IP_MULTICAST_ALL off), a large buffer.
int open_rx(const Side& side, in_addr group, uint16_t port, std::string* err) {
  const int ifindex = interface_index(side, err);
  if (!err->empty()) return -1;
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    *err = std::string("socket: ") + std::strerror(errno);
    return -1;
  }
  const int one = 1, zero = 0, buf = 8 << 20;
  setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
  if (setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &buf, sizeof buf) != 0)
    setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &buf, sizeof buf);
  setsockopt(fd, IPPROTO_IP, IP_MULTICAST_ALL, &zero, sizeof zero);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr = group;
  ip_mreqn m{};
  m.imr_multiaddr = group;
  m.imr_ifindex = ifindex;
  if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &m, sizeof m) != 0) {
    *err = "cannot receive the group in " + side.netns + ": " + std::strerror(errno);
    close(fd);
    return -1;
  }
  return fd;
}

// The sending socket: its own port (known, so its datagrams are recognised when
// they come back), the side's interface, loopback on (receivers may be local).
int open_tx(const Side& side, int ttl, uint16_t* local_port, std::string* err) {
  const int ifindex = interface_index(side, err);
  if (!err->empty()) return -1;
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    *err = std::string("socket: ") + std::strerror(errno);
    return -1;
  }
  const int one = 1;
  setsockopt(fd, IPPROTO_IP, IP_MULTICAST_LOOP, &one, sizeof one);
  setsockopt(fd, IPPROTO_IP, IP_MULTICAST_TTL, &ttl, sizeof ttl);
  if (ifindex != 0) {
    ip_mreqn m{};
    m.imr_ifindex = ifindex;
    if (setsockopt(fd, IPPROTO_IP, IP_MULTICAST_IF, &m, sizeof m) != 0) {
      *err = "cannot send on " + side.ifname + ": " + std::strerror(errno);
      close(fd);
      return -1;
    }
  }
  sockaddr_in a{};
  a.sin_family = AF_INET;
  socklen_t len = sizeof a;
  if (bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0 ||
      getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0) {
    *err = "cannot bind the sending socket in " + side.netns + ": " + std::strerror(errno);
    close(fd);
    return -1;
  }
  *local_port = ntohs(a.sin_port);
  return fd;
}

struct Direction {
  std::string name;
  int rx = -1, tx = -1;
  uint16_t tx_port = 0;
  std::vector<uint16_t> own_ports;  // our sending ports in rx's namespace
  std::unique_ptr<Impairment> imp;
  std::unique_ptr<DelayQueue> queue;
  Counters n;
  char scratch[65536];
};

void receive_all(Direction& d) {
  for (;;) {
    char* buf = d.queue->reserve();
    const bool to_scratch = buf == nullptr;
    if (to_scratch) buf = d.scratch;
    sockaddr_in from{};
    socklen_t flen = sizeof from;
    // MSG_TRUNC: the datagram's real length, to tell one that does not fit.
    const ssize_t r = recvfrom(d.rx, buf, d.queue->slot_bytes(), MSG_TRUNC,
                               reinterpret_cast<sockaddr*>(&from), &flen);
    if (r < 0) return;  // EAGAIN: all read (other errors: read again at the next poll)
    const int64_t t = now_ns();
    bool ours = false;
    for (uint16_t p : d.own_ports) ours = ours || ntohs(from.sin_port) == p;
    if (ours) continue;
    ++d.n.received;
    int64_t release = 0;
    if (!d.imp->admit(t, &release)) {
      ++d.n.lost;
    } else if (static_cast<size_t>(r) > d.queue->slot_bytes()) {
      ++d.n.too_large;
    } else if (to_scratch) {
      ++d.n.queue_full;
    } else {
      d.queue->commit(buf, static_cast<size_t>(r), t, release);
    }
  }
}

void send_due(Direction& d, const sockaddr_in& dest) {
  const int64_t t = now_ns();
  while (d.queue->size() > 0 && d.queue->next_release_ns() <= t) {
    const auto& h = d.queue->front();
    if (sendto(d.tx, h.data, h.bytes, 0, reinterpret_cast<const sockaddr*>(&dest), sizeof dest) < 0)
      ++d.n.send_errors;
    else
      d.n.on_sent(h, t);
    d.queue->pop();
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string group_arg, from_arg, to_arg;
  Params p;
  bool both = false;
  double loss_pct = 0;
  uint64_t queue_slots = 4096, slot_bytes = 65536, ttl = 1, rt_prio = 50;
  CLI::App app{"a loss-and-delay forwarder for a cell's UDP multicast between network namespaces", "cnc-netem"};
  cnc::util::cli::setup(app);
  app.footer("NETNS: /proc/PID/ns/net, /run/netns/NAME or . (this process's namespace); IF: the interface to use");
  app.add_option("--group", group_arg, "the multicast group, e.g. 239.255.76.67:7667")->type_name("ADDR:PORT")->required();
  app.add_option("--from", from_arg, "the side the datagrams are received on")->type_name("NETNS[,IF]")->required();
  app.add_option("--to", to_arg, "the side they are sent again on")->type_name("NETNS[,IF]")->required();
  app.add_flag("--both", both, "forward the other way too (the same parameters, the seed + 1)");
  app.add_option("--loss", loss_pct, "datagrams dropped at random, percent")->type_name("PCT");
  app.add_option("--delay", p.delay_ms, "delay, ms")->type_name("MS");
  app.add_option("--jitter", p.jitter_ms, "delay varies by up to ± this, ms")->type_name("MS");
  app.add_flag("--keep-order", p.keep_order, "never reorder (a datagram waits for the ones before it)");
  app.add_option("--seed", p.seed, "the random generator's seed")->type_name("N");
  app.add_option("--queue", queue_slots, "datagrams held at most")->type_name("N")->check(CLI::Range(1, 65536));
  app.add_option("--slot-bytes", slot_bytes, "largest datagram, bytes")->type_name("N")->check(CLI::Range(64, 65536));
  app.add_option("--ttl", ttl, "the multicast TTL of what it sends")->type_name("N")->check(CLI::Range(0, 255));
  app.add_option("--realtime-priority", rt_prio, "SCHED_FIFO priority (0: normal priority)")
      ->type_name("N")
      ->check(CLI::Range(0, 98));
  if (const int rc = cnc::util::cli::parse(app, argc, argv); rc >= 0) return rc;
  p.loss = loss_pct / 100.0;
  if (const std::string why = cnc::netem::validate(p); !why.empty()) return bad(why);
  const auto colon = group_arg.rfind(':');
  in_addr group{};
  uint64_t port = 0;
  if (colon == std::string::npos || inet_pton(AF_INET, group_arg.substr(0, colon).c_str(), &group) != 1 ||
      !parse_u64(group_arg.substr(colon + 1), &port) || port < 1 || port > 65535 ||
      !IN_MULTICAST(ntohl(group.s_addr)))
    return bad("--group '" + group_arg + "' is not a multicast ADDR:PORT (e.g. 239.255.76.67:7667)");
  Side from, to;
  std::string err;
  if (!parse_side("--from", from_arg, &from, &err) || !parse_side("--to", to_arg, &to, &err)) return bad(err);

  const int home = open("/proc/self/ns/net", O_RDONLY | O_CLOEXEC);
  if (home < 0) {
    std::fprintf(stderr, "cnc-netem: /proc/self/ns/net: %s\n", std::strerror(errno));
    return 1;
  }
  const size_t ndir = both ? 2 : 1;
  std::vector<std::unique_ptr<Direction>> dirs;
  const Side* rx_side[2] = {&from, &to};
  const Side* tx_side[2] = {&to, &from};
  for (size_t k = 0; k < ndir; ++k) {
    auto d = std::make_unique<Direction>();
    d->name = rx_side[k]->netns + " -> " + tx_side[k]->netns;
    Params pk = p;
    pk.seed = p.seed + k;
    d->imp = std::make_unique<Impairment>(pk);
    d->queue = std::make_unique<DelayQueue>(queue_slots, slot_bytes);
    {
      NetnsGuard g(home, *rx_side[k], &err);
      if (err.empty()) d->rx = open_rx(*rx_side[k], group, static_cast<uint16_t>(port), &err);
    }
    if (err.empty()) {
      NetnsGuard g(home, *tx_side[k], &err);
      if (err.empty()) d->tx = open_tx(*tx_side[k], static_cast<int>(ttl), &d->tx_port, &err);
    }
    if (!err.empty()) {
      std::fprintf(stderr, "cnc-netem: %s\n", err.c_str());
      return 1;
    }
    dirs.push_back(std::move(d));
  }
  // A direction ignores what any direction sends into its receiving namespace.
  for (size_t j = 0; j < ndir; ++j)
    for (size_t k = 0; k < ndir; ++k)
      if (tx_side[k]->dev == rx_side[j]->dev && tx_side[k]->ino == rx_side[j]->ino)
        dirs[j]->own_ports.push_back(dirs[k]->tx_port);

  cnc::util::install_stop_handlers();
  if (rt_prio > 0) {
    // SCHED_FIFO only: no mlockall, which would fault in and lock every slot of the
    // queues (256 MiB each by default); the slots in use are touched once and stay.
    sched_param sp{};
    sp.sched_priority = static_cast<int>(rt_prio);
    if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0)
      std::fprintf(stderr, "cnc-netem: SCHED_FIFO %d not permitted (%s): runs at normal priority\n",
                   sp.sched_priority, std::strerror(errno));
  }
  for (const auto& d : dirs)
    std::fprintf(stderr, "cnc-netem: %s: group %s, loss %.2f %%, delay %.3f ± %.3f ms, %s, seed %llu, queue %llu\n",
                 d->name.c_str(), group_arg.c_str(), p.loss * 100.0, p.delay_ms, p.jitter_ms,
                 p.keep_order ? "order kept" : "reordering allowed", static_cast<unsigned long long>(d->imp->params().seed),
                 static_cast<unsigned long long>(queue_slots));
  if (rt_prio > 0 && sched_getscheduler(0) == SCHED_FIFO)
    std::fprintf(stderr, "cnc-netem: SCHED_FIFO %llu\n", static_cast<unsigned long long>(rt_prio));

  sockaddr_in dest{};
  dest.sin_family = AF_INET;
  dest.sin_port = htons(static_cast<uint16_t>(port));
  dest.sin_addr = group;
  pollfd fds[2]{};
  for (size_t k = 0; k < ndir; ++k) fds[k] = pollfd{dirs[k]->rx, POLLIN, 0};
  while (!cnc::util::stop_requested()) {
    int64_t next = std::numeric_limits<int64_t>::max();
    for (const auto& d : dirs) next = std::min(next, d->queue->next_release_ns());
    // At most 100 ms: the stop flag is seen soon after a signal.
    const int64_t wait_ns = std::clamp<int64_t>(next - now_ns(), 0, 100'000'000);
    const timespec ts{static_cast<time_t>(wait_ns / 1'000'000'000), static_cast<long>(wait_ns % 1'000'000'000)};
    const int r = ppoll(fds, ndir, &ts, nullptr);
    if (r < 0 && errno != EINTR) {
      std::fprintf(stderr, "cnc-netem: ppoll: %s\n", std::strerror(errno));
      return 1;
    }
    for (size_t k = 0; k < ndir; ++k)
      if (r > 0 && (fds[k].revents & POLLIN)) receive_all(*dirs[k]);
    for (auto& d : dirs) send_due(*d, dest);
  }
  for (auto& d : dirs) {
    d->n.left_in_queue = static_cast<int64_t>(d->queue->size());
    std::fprintf(stderr, "cnc-netem: %s\n", d->n.summary(d->name).c_str());
  }
  return 0;
}
