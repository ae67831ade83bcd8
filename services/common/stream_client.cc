#include "common/stream_client.h"

#include <algorithm>

namespace lfrecon::svc {

StreamClient::StreamClient(zmq::context_t& context, const std::string& endpoint, std::int64_t max_message_bytes,
                           const ClientSecurity& security)
    : endpoint_(endpoint), max_message_bytes_(max_message_bytes), socket_(context, zmq::socket_type::dealer) {
  CheckClientEndpoint(endpoint, security);
  ConfigureSocket(socket_, max_message_bytes);
  ApplyClientSecurity(socket_, security);
  socket_.connect(endpoint);
}

void StreamClient::Send(const pb::Envelope& env, std::chrono::milliseconds timeout) {
  SetSendTimeout(socket_, timeout);
  // As a REQ socket frames it: an empty delimiter, then the envelope (the daemon's ROUTER echoes the route).
  if (!socket_.send(zmq::message_t(), zmq::send_flags::sndmore))
    throw ServiceError(pb::ERROR_UNKNOWN, "could not send to " + endpoint_ + " within " +
                                              std::to_string(timeout.count()) +
                                              " ms (is lfrecon-ingest running, and does it accept this key?)");
  const std::string bytes = Serialize(env);
  socket_.send(zmq::buffer(bytes), zmq::send_flags::none);  // the rest of a message never blocks
}

std::optional<pb::Envelope> StreamClient::Receive(std::chrono::milliseconds timeout) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    zmq::pollitem_t items[] = {{static_cast<void*>(socket_), 0, ZMQ_POLLIN, 0}};
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(end - std::chrono::steady_clock::now());
    // In slices, so that a signal (StopRequested) ends the wait.
    zmq::poll(items, 1, std::chrono::milliseconds(std::clamp<long long>(left.count(), 0, 200)));
    if (items[0].revents & ZMQ_POLLIN) break;
    if (StopRequested() || std::chrono::steady_clock::now() >= end) return std::nullopt;
  }
  std::vector<zmq::message_t> frames;
  for (;;) {
    zmq::message_t m;
    if (!socket_.recv(m, zmq::recv_flags::dontwait)) break;
    const bool more = m.more();
    frames.push_back(std::move(m));
    if (!more) break;
  }
  pb::Envelope env;
  pb::ErrorReply error;
  if (frames.empty() || !DecodeEnvelope(frames.back().data(), frames.back().size(), max_message_bytes_, &env, &error)) {
    env = NewEnvelope(job_);
    *env.mutable_error() = error;
  }
  return env;
}

pb::Envelope StreamClient::ReceiveOrThrow(std::chrono::milliseconds timeout) {
  auto env = Receive(timeout);
  if (!env)
    throw ServiceError(pb::ERROR_UNKNOWN, "no answer from " + endpoint_ + " within " + std::to_string(timeout.count()) +
                                              " ms (is lfrecon-ingest running?)");
  return *env;
}

pb::StreamOpened StreamClient::Open(const pb::StreamOpen& open, std::chrono::milliseconds timeout) {
  pb::Envelope env = NewEnvelope();
  *env.mutable_stream_open() = open;
  Send(env, timeout);
  const pb::Envelope reply = ReceiveOrThrow(timeout);
  if (reply.has_error()) throw ServiceError(reply.error().code(), reply.error().message());
  if (!reply.has_stream_opened()) throw ServiceError(pb::ERROR_MALFORMED, "StreamOpen answered with " + BodyName(reply));
  job_ = reply.stream_opened().job_id();
  credits_ = static_cast<int>(std::max<std::uint32_t>(1, reply.stream_opened().credits()));
  return reply.stream_opened();
}

void StreamClient::Take(const pb::Envelope& env) {
  --in_flight_;
  if (env.has_error()) throw ServiceError(env.error().code(), env.error().message());
  if (!env.has_stream_credit()) throw ServiceError(pb::ERROR_MALFORMED, "a frame answered with " + BodyName(env));
  const pb::StreamCredit& c = env.stream_credit();
  repeated_ += c.repeated();
  stored_ = std::max(stored_, static_cast<int>(c.frames_stored()));
  max_in_flight_ingest_ = std::max(max_in_flight_ingest_, static_cast<int>(c.max_in_flight()));
}

void StreamClient::Push(const pb::Frame& frame, std::chrono::milliseconds timeout) {
  while (in_flight_ >= credits_) Take(ReceiveOrThrow(timeout));
  pb::Envelope env = NewEnvelope(job_);
  *env.mutable_stream_frame()->mutable_frame() = frame;
  Send(env, timeout);
  ++in_flight_;
  max_in_flight_ = std::max(max_in_flight_, in_flight_);
  // Answers already there are taken now, so errors surface early.
  while (in_flight_ > 0) {
    auto more = Receive(std::chrono::milliseconds(0));
    if (!more) break;
    Take(*more);
  }
}

pb::StreamEnded StreamClient::End(std::uint32_t num_frames, std::chrono::milliseconds timeout) {
  pb::Envelope env = NewEnvelope(job_);
  env.mutable_stream_end()->set_num_frames(num_frames);
  Send(env, timeout);
  for (;;) {
    const pb::Envelope reply = ReceiveOrThrow(timeout);
    if (reply.has_stream_ended()) {
      max_in_flight_ingest_ = std::max(max_in_flight_ingest_, static_cast<int>(reply.stream_ended().max_in_flight()));
      return reply.stream_ended();
    }
    if (in_flight_ == 0) {  // the end's own answer
      if (reply.has_error()) throw ServiceError(reply.error().code(), reply.error().message());
      throw ServiceError(pb::ERROR_MALFORMED, "StreamEnd answered with " + BodyName(reply));
    }
    Take(reply);
  }
}

void StreamClient::SendUnchecked(pb::Envelope env, std::chrono::milliseconds timeout) {
  if (env.job_id().empty()) env.set_job_id(job_);
  Send(env, timeout);
}

}  // namespace lfrecon::svc
