"""A distributed flight on Zenoh: one worker process per radio dongle, a coordinator and a logger
(docs/distributed.md). ``keys`` names the key expressions, ``session`` opens Zenoh sessions, ``auth`` signs the
coordinator's commands, ``bus`` publishes a flight's messages and receives its commands."""
