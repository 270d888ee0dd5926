import Config

config :logger, level: :warning

# A user's own MAVLink dialect (Dolphin.MAVLink.UserDialect): the tests'.
config :dolphin, user_dialects: "test/fixtures/mavlink/user"
