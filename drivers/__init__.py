"""Device drivers: rate table, DAC/ADC front end, FPGA register link, and their protocols."""
