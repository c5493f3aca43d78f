"""Times mcap-ros2-support decoding /joint_states of FILE; prints JSON {count, position_sum, secs}."""
import json
import sys
import time

try:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
except ImportError as e:
    print(f"missing Python package: {e}", file=sys.stderr)
    sys.exit(3)

start = time.perf_counter()
count = 0
position_sum = 0.0
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for _schema, _channel, _message, msg in reader.iter_decoded_messages(topics=["/joint_states"]):
        count += 1
        position_sum += sum(msg.position)
secs = time.perf_counter() - start
json.dump({"count": count, "position_sum": position_sum, "secs": secs}, sys.stdout)
