from fieldbank.cli.main import main

main()
