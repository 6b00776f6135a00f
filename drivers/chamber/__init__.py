"""Temperature chambers: the Watlow F4 controller on Modbus (docs/chamber.md)."""
