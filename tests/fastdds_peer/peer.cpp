// A ROS 2 peer built on Fast DDS 2.9 (eProsima, Debian's libfastrtps-dev): an independent DDS
// implementation that talks to the simulator the way a ROS 2 node on rmw_fastrtps_cpp does.
// Types come from ros2_types.idl (generated from the ROS 2 Jazzy definitions) through fastddsgen.
//
// Usage: fastdds_peer IMU_TOPIC CLOUD_TOPIC IMAGE_TOPIC
//   Subscribes to the three topics and /clock (Reliable, Volatile, KeepLast(10), as ROS 2's default),
//   prints "ready", then reads commands from stdin, one per line:
//     mission TOPIC JSON...            publish std_msgs/String
//     target TOPIC x y z yaw_deg speed publish std_msgs/Float32MultiArray
//     twist TOPIC lx ly lz ax ay az    publish geometry_msgs/Twist
//     report                           print one JSON line: what was received so far
//     quit                             print the report and exit
//   A publish waits (up to 10 s) until the simulator's reader has matched, then answers
//   "sent TOPIC" or "unmatched TOPIC".
// Only loopback: UDPv4 on 127.0.0.1, initial peer 127.0.0.1. Domain from ROS_DOMAIN_ID (default 0).

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "gen/ros2_typesPubSubTypes.h"

using namespace eprosima::fastdds::dds;
namespace ros = sensor_msgs::msg::dds_;

namespace {

std::mutex g_mutex;  // guards every record below (listeners run on Fast DDS threads)

std::string crc32_hex(const std::vector<uint8_t>& bytes) {   // zlib's CRC-32, to compare with Python's
    static uint32_t table[256] = {0};
    if (table[1] == 0) {
        for (uint32_t i = 0; i < 256; ++i) {
            uint32_t c = i;
            for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
            table[i] = c;
        }
    }
    uint32_t crc = 0xFFFFFFFFu;
    for (uint8_t b : bytes) crc = table[(crc ^ b) & 0xFF] ^ (crc >> 8);
    char buf[9];
    std::snprintf(buf, sizeof buf, "%08x", crc ^ 0xFFFFFFFFu);
    return buf;
}

std::string quoted(const std::string& s) {
    std::string out = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') out += '\\';
        out += c;
    }
    return out + "\"";
}

struct Stamped {              // one received sample: header stamp and a hash of its payload
    int32_t sec; uint32_t nanosec; std::string hash;
};

struct Record {
    long count = 0;
    std::string frame_id, extra;          // extra: type-specific JSON members of the last sample
    std::vector<Stamped> samples;
};

std::map<std::string, Record> g_records;   // "imu", "cloud", "image", "clock"

template <class Msg, class Fn>
class Reader : public DataReaderListener {
public:
    explicit Reader(Fn on_sample) : on_sample_(on_sample) {}
    void on_data_available(DataReader* reader) override {
        Msg msg;
        SampleInfo info;
        while (reader->take_next_sample(&msg, &info) == ReturnCode_t::RETCODE_OK) {
            if (!info.valid_data) continue;
            std::lock_guard<std::mutex> lock(g_mutex);
            on_sample_(msg);
        }
    }
private:
    Fn on_sample_;
};

template <class Msg, class Fn>
std::unique_ptr<DataReaderListener> make_reader(Fn fn) { return std::make_unique<Reader<Msg, Fn>>(fn); }

class MatchCounter : public DataWriterListener {
public:
    void on_publication_matched(DataWriter*, const PublicationMatchedStatus& status) override {
        matched = status.current_count;
    }
    std::atomic<int> matched{0};
};

std::string report() {
    std::lock_guard<std::mutex> lock(g_mutex);
    std::ostringstream out;
    out << "{";
    bool first = true;
    for (const auto& [name, rec] : g_records) {
        out << (first ? "" : ",") << quoted(name) << ":{\"count\":" << rec.count
            << ",\"frame_id\":" << quoted(rec.frame_id) << rec.extra << ",\"samples\":[";
        for (size_t i = 0; i < rec.samples.size(); ++i) {
            const auto& s = rec.samples[i];
            out << (i ? "," : "") << "[" << s.sec << "," << s.nanosec << "," << quoted(s.hash) << "]";
        }
        out << "]}";
        first = false;
    }
    out << "}";
    return out.str();
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 4) {
        std::cerr << "usage: fastdds_peer IMU_TOPIC CLOUD_TOPIC IMAGE_TOPIC" << std::endl;
        return 2;
    }
    const char* env_domain = std::getenv("ROS_DOMAIN_ID");
    const int domain = env_domain && *env_domain ? std::atoi(env_domain) : 0;

    DomainParticipantQos pqos;
    pqos.name("fastdds_peer");
    // FASTDDS_PEER_DEFAULTS set: Fast DDS' own defaults (every interface, multicast discovery), as
    // rmw_fastrtps_cpp under ROS 2's default discovery range; else loopback with 127.0.0.1 as peer
    if (!std::getenv("FASTDDS_PEER_DEFAULTS")) {
        auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
        udp->interfaceWhiteList.emplace_back("127.0.0.1");
        pqos.transport().user_transports.push_back(udp);
        pqos.transport().use_builtin_transports = false;
        eprosima::fastrtps::rtps::Locator_t peer;
        eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, 127, 0, 0, 1);
        pqos.wire_protocol().builtin.initialPeersList.push_back(peer);
    }
    // FASTDDS_PEER_RCVBUF=<bytes>: the receive socket buffer a user raises for large best-effort data
    if (const char* rcvbuf = std::getenv("FASTDDS_PEER_RCVBUF")) {
        pqos.transport().listen_socket_buffer_size = static_cast<uint32_t>(std::atol(rcvbuf));
        for (auto& t : pqos.transport().user_transports) {
            auto udp = std::dynamic_pointer_cast<eprosima::fastdds::rtps::UDPv4TransportDescriptor>(t);
            if (udp) udp->receiveBufferSize = static_cast<uint32_t>(std::atol(rcvbuf));
        }
    }
    DomainParticipant* dp = DomainParticipantFactory::get_instance()->create_participant(domain, pqos);
    if (dp == nullptr) { std::cerr << "cannot create a participant" << std::endl; return 1; }

    TypeSupport types[] = {TypeSupport(new ros::Imu_PubSubType()), TypeSupport(new ros::PointCloud2_PubSubType()),
                           TypeSupport(new ros::Image_PubSubType()),
                           TypeSupport(new rosgraph_msgs::msg::dds_::Clock_PubSubType()),
                           TypeSupport(new std_msgs::msg::dds_::String_PubSubType()),
                           TypeSupport(new std_msgs::msg::dds_::Float32MultiArray_PubSubType()),
                           TypeSupport(new geometry_msgs::msg::dds_::Twist_PubSubType())};
    for (auto& t : types) t.register_type(dp);

    Subscriber* sub = dp->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
    Publisher* pub = dp->create_publisher(PUBLISHER_QOS_DEFAULT);
    DataReaderQos rqos = DATAREADER_QOS_DEFAULT;
    // FASTDDS_PEER_BEST_EFFORT set: best-effort readers, as qos_profile_sensor_data and `ros2 topic hz`
    rqos.reliability().kind = std::getenv("FASTDDS_PEER_BEST_EFFORT") ? BEST_EFFORT_RELIABILITY_QOS
                                                                      : RELIABLE_RELIABILITY_QOS;
    rqos.durability().kind = VOLATILE_DURABILITY_QOS;
    rqos.history().kind = KEEP_LAST_HISTORY_QOS;
    rqos.history().depth = 10;
    // unbounded sequences (images, clouds) need a reallocating sample pool on the reader side
    rqos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    DataWriterQos wqos = DATAWRITER_QOS_DEFAULT;
    wqos.reliability().kind = RELIABLE_RELIABILITY_QOS;
    wqos.durability().kind = VOLATILE_DURABILITY_QOS;
    wqos.history().kind = KEEP_LAST_HISTORY_QOS;
    wqos.history().depth = 10;
    wqos.representation().m_value.push_back(XCDR_DATA_REPRESENTATION);
    wqos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;

    auto dds_name = [](const std::string& ros_topic) { return "rt" + ros_topic; };
    std::vector<std::unique_ptr<DataReaderListener>> listeners;
    auto subscribe = [&](const std::string& ros_topic, const std::string& type, std::unique_ptr<DataReaderListener> l) {
        Topic* topic = dp->create_topic(dds_name(ros_topic), type, TOPIC_QOS_DEFAULT);
        if (topic == nullptr || sub->create_datareader(topic, rqos, l.get()) == nullptr) {
            std::cerr << "cannot subscribe to " << ros_topic << std::endl;
            std::exit(1);
        }
        listeners.push_back(std::move(l));
    };

    subscribe(argv[1], "sensor_msgs::msg::dds_::Imu_", make_reader<ros::Imu_>([](const ros::Imu_& m) {
        Record& r = g_records["imu"];
        r.count++;
        r.frame_id = m.header().frame_id();
        const auto& a = m.linear_acceleration();
        std::ostringstream e;
        e << ",\"linear_acceleration\":[" << a.x() << "," << a.y() << "," << a.z() << "],\"orientation_w\":"
          << m.orientation().w();
        r.extra = e.str();
        r.samples.push_back({m.header().stamp().sec(), m.header().stamp().nanosec(), ""});
    }));
    subscribe(argv[2], "sensor_msgs::msg::dds_::PointCloud2_", make_reader<ros::PointCloud2_>([](const ros::PointCloud2_& m) {
        Record& r = g_records["cloud"];
        r.count++;
        r.frame_id = m.header().frame_id();
        std::ostringstream e;
        e << ",\"width\":" << m.width() << ",\"height\":" << m.height() << ",\"point_step\":" << m.point_step()
          << ",\"fields\":[";
        for (size_t i = 0; i < m.fields().size(); ++i) e << (i ? "," : "") << quoted(m.fields()[i].name());
        e << "]";
        r.extra = e.str();
        r.samples.push_back({m.header().stamp().sec(), m.header().stamp().nanosec(), crc32_hex(m.data())});
    }));
    subscribe(argv[3], "sensor_msgs::msg::dds_::Image_", make_reader<ros::Image_>([](const ros::Image_& m) {
        Record& r = g_records["image"];
        r.count++;
        r.frame_id = m.header().frame_id();
        std::ostringstream e;
        e << ",\"width\":" << m.width() << ",\"height\":" << m.height() << ",\"step\":" << m.step()
          << ",\"encoding\":" << quoted(m.encoding()) << ",\"bytes\":" << m.data().size();
        r.extra = e.str();
        r.samples.push_back({m.header().stamp().sec(), m.header().stamp().nanosec(), crc32_hex(m.data())});
    }));
    subscribe("/clock", "rosgraph_msgs::msg::dds_::Clock_",
              make_reader<rosgraph_msgs::msg::dds_::Clock_>([](const rosgraph_msgs::msg::dds_::Clock_& m) {
        Record& r = g_records["clock"];
        r.count++;
        std::ostringstream e;
        e << ",\"last\":[" << m.clock().sec() << "," << m.clock().nanosec() << "]";
        r.extra = e.str();
    }));

    struct Writer { DataWriter* writer; std::unique_ptr<MatchCounter> matched; };
    std::map<std::string, Writer> writers;
    auto writer_for = [&](const std::string& ros_topic, const std::string& type) -> Writer& {
        auto it = writers.find(ros_topic);
        if (it != writers.end()) return it->second;
        auto counter = std::make_unique<MatchCounter>();
        Topic* topic = dp->create_topic(dds_name(ros_topic), type, TOPIC_QOS_DEFAULT);
        DataWriter* w = topic ? pub->create_datawriter(topic, wqos, counter.get()) : nullptr;
        if (w == nullptr) { std::cerr << "cannot publish on " << ros_topic << std::endl; std::exit(1); }
        return writers[ros_topic] = Writer{w, std::move(counter)};
    };
    auto send = [&](const std::string& ros_topic, Writer& w, void* sample) {
        auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
        while (w.matched->matched == 0 && std::chrono::steady_clock::now() < until)
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        if (w.matched->matched == 0) { std::cout << "unmatched " << ros_topic << std::endl; return; }
        std::this_thread::sleep_for(std::chrono::milliseconds(200));   // let the reader finish matching us
        w.writer->write(sample);
        std::cout << "sent " << ros_topic << std::endl;
    };

    std::cout << "ready" << std::endl;
    std::string line;
    while (std::getline(std::cin, line)) {
        std::istringstream in(line);
        std::string cmd, topic;
        in >> cmd;
        if (cmd == "report") { std::cout << report() << std::endl; continue; }
        if (cmd == "quit") break;
        in >> topic;
        if (cmd == "mission") {
            std_msgs::msg::dds_::String_ msg;
            std::string rest;
            std::getline(in >> std::ws, rest);
            msg.data(rest);
            send(topic, writer_for(topic, "std_msgs::msg::dds_::String_"), &msg);
        } else if (cmd == "target") {
            std_msgs::msg::dds_::Float32MultiArray_ msg;
            float v;
            while (in >> v) msg.data().push_back(v);
            send(topic, writer_for(topic, "std_msgs::msg::dds_::Float32MultiArray_"), &msg);
        } else if (cmd == "twist") {
            geometry_msgs::msg::dds_::Twist_ msg;
            double v[6] = {0, 0, 0, 0, 0, 0};
            for (double& x : v) in >> x;
            msg.linear().x(v[0]); msg.linear().y(v[1]); msg.linear().z(v[2]);
            msg.angular().x(v[3]); msg.angular().y(v[4]); msg.angular().z(v[5]);
            send(topic, writer_for(topic, "geometry_msgs::msg::dds_::Twist_"), &msg);
        } else {
            std::cout << "error unknown command " << quoted(cmd) << std::endl;
        }
    }
    std::cout << report() << std::endl;
    dp->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(dp);
    return 0;
}
