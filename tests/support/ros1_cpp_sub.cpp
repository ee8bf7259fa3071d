// An independent ROS 1 subscriber for the ros1_latency bench, built against Debian's roscpp
// (libroscpp-dev, libsensor-msgs-dev) by bridge/src/bin/common/roscpp.rs.
//
//   ros1_cpp_sub TOPIC image|cloud
//
// Subscribes with TCP_NODELAY, prints "ready", then for each message one line
// "ARRIVAL_NS STAMP_NS": CLOCK_MONOTONIC when the callback got the message (deserialized, data
// in hand) and the header stamp read as nanoseconds (the bench writes CLOCK_MONOTONIC there).
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <string>

static unsigned long long monotonic_ns() {
  timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (unsigned long long)t.tv_sec * 1000000000ULL + t.tv_nsec;
}

template <class M>
static void on_message(const boost::shared_ptr<const M>& m) {
  const unsigned long long now = monotonic_ns();
  const unsigned long long stamp =
      (unsigned long long)(uint32_t)m->header.stamp.sec * 1000000000ULL + m->header.stamp.nsec;
  std::printf("%llu %llu\n", now, stamp);
  std::fflush(stdout);
}

int main(int argc, char** argv) {
  ros::init(argc, argv, "perturb_latency_cpp_sub", ros::init_options::AnonymousName);
  if (argc < 3) {
    std::fprintf(stderr, "usage: ros1_cpp_sub TOPIC image|cloud\n");
    return 2;
  }
  const std::string topic = argv[1];
  ros::NodeHandle nh;
  ros::Subscriber sub;
  const ros::TransportHints hints = ros::TransportHints().tcpNoDelay();
  if (std::strcmp(argv[2], "cloud") == 0) {
    sub = nh.subscribe<sensor_msgs::PointCloud2>(topic, 4, on_message<sensor_msgs::PointCloud2>,
                                                 hints);
  } else {
    sub = nh.subscribe<sensor_msgs::Image>(topic, 4, on_message<sensor_msgs::Image>, hints);
  }
  std::printf("ready\n");
  std::fflush(stdout);
  ros::spin();
  return 0;
}
