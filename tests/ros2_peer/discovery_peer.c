/* An independent DDS peer for tests/test_ros2_wire.py: Debian's Cyclone DDS C library (the
 * version line ROS 2 Humble and Jazzy ship) joins a domain and prints, for every writer it
 * discovers within the given time, one line:
 *   topic<TAB>type<TAB>reliability<TAB>history<TAB>depth<TAB>durability<TAB>user data
 * reliability: reliable|best_effort; history: keep_last|keep_all; durability: volatile|
 * transient_local|other. Usage: discovery_peer DOMAIN SECONDS */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "dds/dds.h"

static const char *reliability_name(const dds_qos_t *qos) {
  dds_reliability_kind_t kind;
  dds_duration_t blocking;
  if (!dds_qget_reliability(qos, &kind, &blocking)) return "unset";
  return kind == DDS_RELIABILITY_RELIABLE ? "reliable" : "best_effort";
}

int main(int argc, char **argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: %s DOMAIN SECONDS\n", argv[0]);
    return 2;
  }
  dds_entity_t participant = dds_create_participant((dds_domainid_t)atoi(argv[1]), NULL, NULL);
  if (participant < 0) return 1;
  dds_entity_t reader = dds_create_reader(participant, DDS_BUILTIN_TOPIC_DCPSPUBLICATION, NULL, NULL);
  if (reader < 0) return 1;
  dds_time_t end = dds_time() + (dds_time_t)(atof(argv[2]) * 1e9);
  void *samples[16] = {NULL};
  dds_sample_info_t infos[16];
  while (dds_time() < end) {
    int count = dds_take(reader, samples, infos, 16, 16);
    for (int i = 0; i < count; i++) {
      if (!infos[i].valid_data) continue;
      const dds_builtintopic_endpoint_t *writer = samples[i];
      dds_history_kind_t history;
      int32_t depth = 0;
      dds_durability_kind_t durability;
      void *user = NULL;
      size_t user_size = 0;
      if (!dds_qget_history(writer->qos, &history, &depth)) history = DDS_HISTORY_KEEP_LAST;
      if (!dds_qget_durability(writer->qos, &durability)) durability = DDS_DURABILITY_VOLATILE;
      dds_qget_userdata(writer->qos, &user, &user_size);
      printf("%s\t%s\t%s\t%s\t%d\t%s\t%.*s\n", writer->topic_name, writer->type_name,
             reliability_name(writer->qos),
             history == DDS_HISTORY_KEEP_LAST ? "keep_last" : "keep_all", (int)depth,
             durability == DDS_DURABILITY_VOLATILE ? "volatile"
             : durability == DDS_DURABILITY_TRANSIENT_LOCAL ? "transient_local" : "other",
             (int)user_size, user ? (const char *)user : "");
      fflush(stdout);
      dds_free(user);
    }
    if (count > 0) dds_return_loan(reader, samples, count);
    dds_sleepfor(DDS_MSECS(10));
  }
  dds_delete(participant);
  return 0;
}
