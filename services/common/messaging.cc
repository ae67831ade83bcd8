#include "messaging.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cstdlib>
#include <limits>

namespace lfrecon::svc {
namespace {
// zmq::poll that treats a signal (EINTR) as a timeout.
void PollInterruptible(zmq::pollitem_t* items, std::chrono::milliseconds timeout) {
  try {
    zmq::poll(items, 1, timeout);
  } catch (const zmq::error_t& e) {
    if (e.num() != EINTR) throw;
    items[0].revents = 0;
  }
}
}  // namespace

std::string EndpointFromEnv(const char* name, const std::string& fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::string(v) : fallback;
}

pb::Envelope NewEnvelope(const std::string& job_id) {
  pb::Envelope env;
  env.set_version(kProtocolVersion);
  env.set_job_id(job_id);
  return env;
}

pb::Envelope ErrorEnvelope(pb::ErrorCode code, const std::string& message, const std::string& job_id) {
  pb::Envelope env = NewEnvelope(job_id);
  env.mutable_error()->set_code(code);
  env.mutable_error()->set_message(message);
  return env;
}

std::string Serialize(const pb::Envelope& env) {
  std::string out;
  if (!env.SerializeToString(&out)) throw std::runtime_error("cannot serialize a " + BodyName(env) + " message");
  return out;
}

bool DecodeEnvelope(const void* data, std::size_t size, std::int64_t max_message_bytes, pb::Envelope* env,
                    pb::ErrorReply* error) {
  if (static_cast<std::int64_t>(size) > max_message_bytes) {
    error->set_code(pb::ERROR_TOO_LARGE);
    error->set_message("message of " + std::to_string(size) + " bytes exceeds the limit of " +
                       std::to_string(max_message_bytes) + " bytes");
    return false;
  }
  if (!env->ParseFromArray(data, static_cast<int>(size))) {
    error->set_code(pb::ERROR_MALFORMED);
    error->set_message("malformed message (" + std::to_string(size) + " bytes): not a lfrecon.v1.Envelope");
    return false;
  }
  if (env->version() == 0) {  // proto3: an absent field reads 0; every sender sets it
    error->set_code(pb::ERROR_MALFORMED);
    error->set_message("message without a protocol version (" + std::to_string(size) + " bytes)");
    return false;
  }
  if (env->version() != kProtocolVersion) {
    error->set_code(pb::ERROR_VERSION);
    error->set_message("protocol version " + std::to_string(env->version()) + " not supported (this daemon speaks " +
                       std::to_string(kProtocolVersion) + ")");
    return false;
  }
  if (env->body_case() == pb::Envelope::BODY_NOT_SET) {
    error->set_code(pb::ERROR_MALFORMED);
    error->set_message("message has no body");
    return false;
  }
  return true;
}

std::string BodyName(const pb::Envelope& env) {
  const auto* field = pb::Envelope::descriptor()->FindFieldByNumber(static_cast<int>(env.body_case()));
  return field ? field->name() : "empty";
}

void ConfigureSocket(zmq::socket_t& socket, std::int64_t max_message_bytes) {
  socket.set(zmq::sockopt::linger, 0);
  socket.set(zmq::sockopt::maxmsgsize, TransportLimit(max_message_bytes));
}

void SetSendTimeout(zmq::socket_t& socket, std::chrono::milliseconds timeout) {
  socket.set(zmq::sockopt::sndtimeo,
             static_cast<int>(std::clamp<std::chrono::milliseconds::rep>(timeout.count(), 0, std::numeric_limits<int>::max())));
}

RequestClient::RequestClient(zmq::context_t& context, std::string endpoint, std::int64_t max_message_bytes,
                             ClientSecurity security)
    : context_(context), endpoint_(std::move(endpoint)), max_message_bytes_(max_message_bytes),
      security_(std::move(security)) {
  CheckClientEndpoint(endpoint_, security_);
  Reset();
}

void RequestClient::Reset() {
  socket_.reset();
  socket_.emplace(context_, zmq::socket_type::req);
  ConfigureSocket(*socket_, max_message_bytes_);
  ApplyClientSecurity(*socket_, security_);
  socket_->connect(endpoint_);
}

std::optional<pb::Envelope> RequestClient::RequestRaw(const std::string& bytes, std::chrono::milliseconds timeout) {
  SetSendTimeout(*socket_, timeout);  // the same bound as the reply's, not forever
  if (!socket_->send(zmq::buffer(bytes), zmq::send_flags::none)) {
    Reset();
    return std::nullopt;
  }
  zmq::pollitem_t items[] = {{static_cast<void*>(*socket_), 0, ZMQ_POLLIN, 0}};
  PollInterruptible(items, timeout);
  if (!(items[0].revents & ZMQ_POLLIN)) {
    Reset();  // a REQ socket that missed its reply cannot send again
    return std::nullopt;
  }
  zmq::message_t msg;
  if (!socket_->recv(msg, zmq::recv_flags::none)) {
    Reset();
    return std::nullopt;
  }
  pb::Envelope env;
  pb::ErrorReply error;
  if (!DecodeEnvelope(msg.data(), msg.size(), max_message_bytes_, &env, &error)) {
    env = NewEnvelope();
    *env.mutable_error() = error;
  }
  return env;
}

std::optional<pb::Envelope> RequestClient::Request(const pb::Envelope& request, std::chrono::milliseconds timeout,
                                                   int attempts) {
  const std::string bytes = Serialize(request);
  for (int a = 0; a < std::max(1, attempts); ++a) {
    auto reply = RequestRaw(bytes, timeout);
    if (reply) return reply;
    spdlog::debug("no reply from {} within {} ms (attempt {}/{})", endpoint_, timeout.count(), a + 1, attempts);
  }
  return std::nullopt;
}

pb::Envelope RequestClient::Call(const pb::Envelope& request, std::chrono::milliseconds timeout, int attempts) {
  auto reply = Request(request, timeout, attempts);
  if (!reply)
    throw ServiceError(pb::ERROR_UNKNOWN, "no reply from " + endpoint_ + " (is the daemon running?)");
  if (reply->has_error()) throw ServiceError(reply->error().code(), reply->error().message());
  return *reply;
}

RouterServer::RouterServer(zmq::context_t& context, const std::string& endpoint, std::int64_t max_message_bytes,
                           const ServerSecurity& security)
    : max_message_bytes_(max_message_bytes), curve_(security.curve()), socket_(context, zmq::socket_type::router) {
  CheckServerEndpoint(endpoint, security);
  ConfigureSocket(socket_, max_message_bytes);
  if (curve_) {
    zap_ = std::make_unique<ZapHandler>(context, security.allow);
    ApplyServerSecurity(socket_, security);
  }
  socket_.bind(endpoint);
  if (curve_)
    spdlog::info("{}: CURVE, {} allowed keys, public key {}", endpoint, security.allow->size(),
                 security.key->public_key);
  else if (security.insecure && endpoint.rfind("tcp://", 0) == 0)
    spdlog::warn("{}: plain TCP (--insecure): anyone who reaches it can send anything, unencrypted", endpoint);
}

std::optional<RouterServer::Incoming> RouterServer::Receive(std::chrono::milliseconds timeout) {
  zmq::pollitem_t items[] = {{static_cast<void*>(socket_), 0, ZMQ_POLLIN, 0}};
  PollInterruptible(items, timeout);
  if (!(items[0].revents & ZMQ_POLLIN)) return std::nullopt;
  std::vector<zmq::message_t> frames;
  while (true) {
    zmq::message_t m;
    if (!socket_.recv(m, zmq::recv_flags::dontwait)) break;
    const bool more = m.more();
    frames.push_back(std::move(m));
    if (!more) break;
  }
  if (frames.size() < 2) return std::nullopt;  // no identity + payload: nothing to answer
  Incoming in;
  zmq::message_t payload = std::move(frames.back());
  frames.pop_back();
  in.route = std::move(frames);
  in.bytes = payload.size();
  in.role = curve_ ? PeerRole(payload, &in.peer, &in.peer_key) : Role::kLocal;
  in.ok = DecodeEnvelope(payload.data(), payload.size(), max_message_bytes_, &in.envelope, &in.error);
  if (in.ok && !RoleMaySend(in.role, in.envelope.body_case())) {
    in.ok = false;
    in.error.set_code(pb::ERROR_FORBIDDEN);
    in.error.set_message(std::string("a ") + RoleName(in.role) + " key (" + (in.peer.empty() ? "?" : in.peer) +
                         ") may not send '" + BodyName(in.envelope) + "'");
  }
  return in;
}

void RouterServer::Reply(Incoming& in, const pb::Envelope& reply) {
  for (auto& r : in.route) socket_.send(r, zmq::send_flags::sndmore);
  const std::string bytes = Serialize(reply);
  if (static_cast<std::int64_t>(bytes.size()) > max_message_bytes_) {
    const std::string err = Serialize(ErrorEnvelope(
        pb::ERROR_TOO_LARGE, "reply of " + std::to_string(bytes.size()) + " bytes exceeds the limit", reply.job_id()));
    socket_.send(zmq::buffer(err), zmq::send_flags::none);
    return;
  }
  socket_.send(zmq::buffer(bytes), zmq::send_flags::none);
}

namespace {
std::atomic<bool> g_stop{false};
extern "C" void OnStopSignal(int) { g_stop = true; }
}  // namespace

void InstallStopHandlers() {
  std::signal(SIGINT, OnStopSignal);
  std::signal(SIGTERM, OnStopSignal);
}
bool StopRequested() { return g_stop.load(); }

}  // namespace lfrecon::svc
