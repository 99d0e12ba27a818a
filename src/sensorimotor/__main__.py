from sensorimotor.cli import main

main()
